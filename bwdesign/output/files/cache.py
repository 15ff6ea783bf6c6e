"""The result cache: what bwdesign keeps between runs, outside every output directory.

A command whose work is a pure function of its inputs (the study of a stage file,
:mod:`bwdesign.study.cache`) may keep the result here under a key its caller
computes from everything the result depends on. The store knows nothing of what it
holds; it only promises:

- **Where.** ``$BWDESIGN_CACHE_DIR``, else ``$XDG_CACHE_HOME/bwdesign``, else
  ``~/.cache/bwdesign`` (:func:`default_cache_dir`); a relative path is taken from the
  current directory. Never an output directory: nothing here is a command's output.
- **Entries.** One file ``<key>.<kind>`` per entry (``key`` lowercase hex, ``kind`` a
  short word), starting with the line ``bwdesign-cache 1 <sha256 of the rest>``.
  Written to a temporary file in the same folder and renamed into place
  (:func:`os.replace`), so a reader sees a whole entry or none; the folder is created
  ``0700``, entries ``0600``.
- **Reading never fails.** A missing entry, a short or damaged one (the checksum does
  not match), one that is not a regular file, not owned by this user or writable by
  others, reads as a miss (``None``): the caller computes the result again.
- **Writing never fails.** A folder that cannot be created or written keeps nothing
  (:meth:`ResultCache.write` returns ``False``); nothing is written once the command
  line recorded a Ctrl-C (:func:`bwdesign.interrupts.pending`).
- **Size.** After a write, the oldest entries beyond :data:`MAX_ENTRIES` are removed (a
  report keeps two: its study and its figures).
  Only files whose names and first line are an entry's are ever removed or replaced:
  anything else in the folder is left alone.
"""

from __future__ import annotations

import hashlib
import os
import re
import stat
import tempfile
from pathlib import Path

from ... import interrupts
from ...errors import InputError

__all__ = ["ResultCache", "default_cache_dir", "CACHE_ENV", "MAX_ENTRIES"]

#: Environment variable naming the cache folder.
CACHE_ENV = "BWDESIGN_CACHE_DIR"
#: Entries kept; a write removes the oldest beyond this many.
MAX_ENTRIES = 32

_MAGIC = b"bwdesign-cache 1 "
_NAME = re.compile(r"^[0-9a-f]{16,128}\.[a-z]{1,16}$")


def default_cache_dir() -> Path:
    """``$BWDESIGN_CACHE_DIR``, else ``$XDG_CACHE_HOME/bwdesign``, else ``~/.cache/bwdesign``."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return Path(given).expanduser().absolute()
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg and Path(xdg).is_absolute():
        return Path(xdg) / "bwdesign"
    return Path.home() / ".cache" / "bwdesign"


def _ours(st: os.stat_result) -> bool:
    """A regular file of this user that nobody else may write."""
    if not stat.S_ISREG(st.st_mode) or st.st_mode & 0o022:
        return False
    getuid = getattr(os, "getuid", None)
    return getuid is None or st.st_uid == getuid()


class ResultCache:
    """A folder of cache entries (see the module doc for the rules).

    Parameters
    ----------
    root : path, optional
        The folder (default :func:`default_cache_dir`); created on the first write.
    """

    def __init__(self, root: str | os.PathLike[str] | None = None) -> None:
        self.root = default_cache_dir() if root is None else Path(root).absolute()

    def __repr__(self) -> str:
        return f"ResultCache({str(self.root)!r})"

    def path(self, key: str, kind: str) -> Path:
        """Where the entry ``(key, kind)`` lives (whether or not it exists)."""
        name = f"{key}.{kind}"
        if not _NAME.match(name):
            raise InputError(f"not a cache entry name: {name!r} (hex key, short lowercase kind)")
        return self.root / name

    def read(self, key: str, kind: str) -> bytes | None:
        """The payload of an entry, or ``None`` (missing, damaged or not ours: a miss)."""
        try:
            path = self.path(key, kind)
            fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
        except OSError:
            return None
        try:
            with os.fdopen(fd, "rb") as f:
                if not _ours(os.fstat(f.fileno())):
                    return None
                data = f.read()
        except OSError:
            return None
        head, sep, payload = data.partition(b"\n")
        if not sep or not head.startswith(_MAGIC):
            return None
        digest = head[len(_MAGIC) :].decode("ascii", "replace")
        if hashlib.sha256(payload).hexdigest() != digest:
            return None
        try:
            os.utime(path)  # recently used: the last to be pruned
        except OSError:
            pass
        return payload

    def write(self, key: str, kind: str, payload: bytes) -> bool:
        """Keep ``payload`` as the entry ``(key, kind)``, atomically; ``False`` if not kept."""
        path = self.path(key, kind)
        if interrupts.pending():
            return False
        head = _MAGIC + hashlib.sha256(payload).hexdigest().encode("ascii") + b"\n"
        tmp = None
        try:
            self.root.mkdir(mode=0o700, parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=".tmp-", dir=self.root)
            with os.fdopen(fd, "wb") as f:
                f.write(head)
                f.write(payload)
            if interrupts.pending():
                return False
            os.replace(tmp, path)
            tmp = None
        except OSError:
            return False
        finally:
            if tmp is not None:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
        self._prune(keep=path.name)
        return True

    def entries(self) -> list[Path]:
        """The folder's entries (files named and headed as an entry), oldest first."""
        found = []
        try:
            names = os.listdir(self.root)
        except OSError:
            return []
        for name in names:
            if not _NAME.match(name):
                continue
            p = self.root / name
            try:
                st = os.lstat(p)
                if not _ours(st):
                    continue
                with open(p, "rb") as f:
                    if not f.read(len(_MAGIC)) == _MAGIC:
                        continue
            except OSError:
                continue
            found.append((st.st_mtime_ns, name, p))
        return [p for _, _, p in sorted(found)]

    def _prune(self, keep: str) -> None:
        old = [p for p in self.entries() if p.name != keep]
        for p in old[: max(0, len(old) + 1 - MAX_ENTRIES)]:
            try:
                os.unlink(p)
            except OSError:
                pass
