"""Names of staging directories and temporary files, and when a leftover one may go.

A run stages its output under a name that says who owns it: the writing
command, the process id and the host (``socket.gethostname()``, characters
outside ``[A-Za-z0-9._-]`` replaced by ``_``)::

    .bwdesign-tmp-<command>-<pid>@<host>-<hex>/     (directory outputs)
    .<name>.bwdesign-tmp-<pid>@<host>-<hex>         (single files, beside <name>)

A leftover of a killed run is removed by the next run only when that is safe:
its host is this host and no process with its pid runs here, or nothing
changed it for :data:`STALE_AFTER_S` (24 h). A pid says nothing about another
host sharing the folder (NFS, a container volume): such a run's staging is
kept, and the next run refuses the target naming it, until it is 24 h old.
Names from before the host was recorded (``...-<pid>-<hex>``) have an unknown
host and go by age alone.
"""

from __future__ import annotations

import os
import re
import socket
import stat
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "STAGING_PREFIX",
    "STALE_AFTER_S",
    "Owner",
    "file_temporary_name",
    "leftover",
    "pid_alive",
    "staging_name",
    "staging_owner",
    "temporary_owner",
    "this_host",
]

#: Prefix of staging directories (and the infix of single-file temporaries).
STAGING_PREFIX = ".bwdesign-tmp-"
#: A staging directory or temporary unchanged this long (seconds) is a leftover
#: whatever its owner: 24 h.
STALE_AFTER_S = 24 * 3600.0

_OWNER = r"(?P<pid>\d+)(?:@(?P<host>[A-Za-z0-9._-]+))?-[0-9a-f]+"
_STAGING = re.compile(rf"^\.bwdesign-tmp-(?P<slug>[A-Za-z0-9-]+?)-{_OWNER}$")


@dataclass(frozen=True)
class Owner:
    """Who wrote a staging directory or temporary: ``host`` None for old names."""

    pid: int
    host: str | None

    def describe(self) -> str:
        """``pid 123 on host build-01`` (``on an unrecorded host`` for old names)."""
        where = f"on host {self.host}" if self.host is not None else "on an unrecorded host"
        return f"pid {self.pid} {where}"


def this_host() -> str:
    """This host's name as staging names carry it."""
    name = re.sub(r"[^A-Za-z0-9._-]", "_", socket.gethostname())[:64]
    return name or "unnamed-host"


def staging_name(slug: str, token: str) -> str:
    """The staging directory name of this process for the command ``slug``."""
    return f"{STAGING_PREFIX}{slug}-{os.getpid()}@{this_host()}-{token}"


def file_temporary_name(name: str, token: str) -> str:
    """The temporary beside the file ``name`` this process writes."""
    return f".{name}{STAGING_PREFIX}{os.getpid()}@{this_host()}-{token}"


def staging_owner(name: str, slug: str) -> Owner | None:
    """The owner of a staging directory of command ``slug`` (None: not one)."""
    m = _STAGING.match(name)
    if m is None or m["slug"] != slug:
        return None
    return Owner(int(m["pid"]), m["host"])


def temporary_owner(name: str, target: str) -> Owner | None:
    """The owner of a temporary of the file ``target`` (None: not one)."""
    m = re.match(rf"^\.{re.escape(target)}{re.escape(STAGING_PREFIX)}{_OWNER}$", name)
    return None if m is None else Owner(int(m["pid"]), m["host"])


def pid_alive(pid: int) -> bool:
    """A process with this pid runs on this host (this process itself counts as gone)."""
    if pid == os.getpid():
        return False  # a leftover of this process (a writer is not re-entered)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    return True


def leftover(path: Path, owner: Owner) -> bool:
    """True when ``path`` (owned by ``owner``) may be removed: its run is gone.

    Gone means: written on this host by a pid that no longer runs here, or
    unchanged for :data:`STALE_AFTER_S`. A path that vanished is not a leftover.
    """
    try:
        st = os.lstat(path)
    except OSError:
        return False
    if stat.S_ISLNK(st.st_mode):
        return False  # never ours: staging directories and temporaries are real entries
    if owner.host == this_host() and not pid_alive(owner.pid):
        return True
    return time.time() - st.st_mtime > STALE_AFTER_S
