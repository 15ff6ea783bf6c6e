"""What both kinds of output share: names, file checks, writes, error messages."""

from __future__ import annotations

import hashlib
import os
import re
import stat
from pathlib import Path

from ...errors import InputError, OutputError

__all__ = [
    "MANIFEST",
    "check_parent",
    "command_slug",
    "is_writable",
    "kind_of",
    "lstat_or_none",
    "sha256_of",
    "write_error",
    "write_new",
]

#: Name of the manifest a directory output holds.
MANIFEST = ".bwdesign-manifest.json"


def command_slug(command: str) -> str:
    """``command`` as staging names spell it (``"identify --report"``: ``identify-report``)."""
    slug = re.sub(r"[^A-Za-z0-9]+", "-", command).strip("-")
    if not slug:
        raise InputError(f"command must name the writer, got {command!r}")
    return slug


def is_writable(st: os.stat_result, path: Path) -> bool:
    """Writable by us *and* carrying a write bit (root ignores the bits otherwise)."""
    return bool(st.st_mode & 0o222) and os.access(path, os.W_OK | os.X_OK)


def kind_of(st: os.stat_result) -> str:
    mode = st.st_mode
    for test, name in (
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISREG, "a regular file"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def lstat_or_none(path: Path, what: str) -> os.stat_result | None:
    """``os.lstat`` or None when missing; other failures refuse the target."""
    try:
        return os.lstat(path)
    except FileNotFoundError:
        return None
    except NotADirectoryError:
        raise OutputError(f"{what} {str(path)!r}: a parent of it is not a directory") from None
    except OSError as err:
        raise OutputError(f"{what} {str(path)!r}: cannot inspect it ({err.strerror})") from None


def check_parent(path: Path, what: str) -> None:
    """The nearest existing ancestor of ``path`` is a writable directory."""
    parent = Path(os.path.abspath(path)).parent
    while True:
        st = lstat_or_none(parent, what)
        if st is not None:
            break
        parent = parent.parent
    try:
        st = os.stat(parent)  # symlinks above the target are fine (e.g. /tmp)
    except OSError as err:
        raise OutputError(f"{what} {str(path)!r}: cannot inspect {str(parent)!r}") from err
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{what} {str(path)!r}: {str(parent)!r} is not a directory")
    if not is_writable(st, parent):
        raise OutputError(f"{what} {str(path)!r}: directory {str(parent)!r} is not writable")


def sha256_of(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_new(path: Path, data: bytes) -> None:
    """Create ``path`` (must not exist) with mode 0o666 & ~umask, write and flush it."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def write_error(err: OSError, what: str, path: Path) -> OutputError:
    reason = err.strerror or str(err)
    return OutputError(f"{what} {str(path)!r}: cannot write ({reason}); nothing was replaced")
