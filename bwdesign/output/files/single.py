"""Single-file outputs: a signature line, an atomic replace (see the package docstring)."""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import secrets
import stat
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from ... import interrupts
from ..._version import __version__
from ...errors import OutputError
from .common import is_writable, kind_of, lstat_or_none, write_error
from .staging import file_temporary_name, leftover, temporary_owner

__all__ = ["FileTarget", "prepare_file", "signature_line"]


_PLACEHOLDER = "0" * 64


def signature_line(command: str, comment: str = "#", digest: str = _PLACEHOLDER) -> str:
    """First line of a file bwdesign writes.

    ``# written by bwdesign 1.0 (simulate --csv) sha256=<hex>``, the checksum
    being that of every byte after this line: a file edited since is not
    bwdesign's any more.
    """
    return (
        f"{comment} written by bwdesign {__version__} ({command}) sha256={digest}"
        f"{_CLOSERS.get(comment, '')}"
    )


#: Comment markers that need a closing mark on the same line (XML, HTML, C block).
_CLOSERS = {"<!--": " -->", "/*": " */"}


def _signed(path: Path, command: str, comment: str | None) -> bool:
    """``path`` starts with the signature of ``command`` and is unchanged since."""
    if comment is None:
        return False
    pattern = re.compile(
        rf"{re.escape(comment)} written by bwdesign \S+ \({re.escape(command)}\) "
        r"sha256=(?P<h>[0-9a-f]{64})" + re.escape(_CLOSERS.get(comment, ""))
    )
    try:
        with open(path, "rb") as f:
            first = f.readline(1024).decode("utf-8", "replace").rstrip("\r\n")
            m = pattern.fullmatch(first)
            if m is None:
                return False
            h = hashlib.sha256()
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    except OSError:
        return False
    return h.hexdigest() == m["h"]


def _fill_digest(path: Path) -> None:
    """Replace the placeholder checksum in ``path``'s first line by the real one."""
    with open(path, "r+b") as f:
        first = f.readline()
        h = hashlib.sha256()
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
        at = first.rindex(_PLACEHOLDER.encode())
        f.seek(at)
        f.write(h.hexdigest().encode())
        f.flush()
        os.fsync(f.fileno())


@dataclass(frozen=True)
class FileTarget:
    """A single-file output checked by :func:`prepare_file`.

    Attributes
    ----------
    path : Path
    command : str
    comment : str or None
        Comment marker of the signature line; None writes no signature.
    what : str
        Name of the target in messages (``"--csv"``).
    """

    path: Path
    command: str
    comment: str | None = "#"
    what: str = "output file"
    exclusive: bool = False

    @contextlib.contextmanager
    def open(self) -> Iterator[IO[str]]:
        """A text file (UTF-8) to write the contents to; committed atomically on exit.

        The signature line is already written when the block starts.
        """
        token = secrets.token_hex(4)
        tmp = self.path.parent / file_temporary_name(self.path.name, token)
        try:
            try:
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
                with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
                    if self.comment is not None:
                        f.write(signature_line(self.command, self.comment) + "\n")
                    yield f
                if self.comment is not None:
                    _fill_digest(tmp)
                interrupts.check()  # a Ctrl-C something swallowed: the previous file stays
                st = lstat_or_none(self.path, self.what)
                if st is not None and not stat.S_ISREG(st.st_mode):
                    raise OutputError(
                        f"{self.what} {str(self.path)!r} became {kind_of(st)} while bwdesign "
                        "worked; nothing was replaced"
                    )
                if self.exclusive:
                    # a hard link fails when the target exists: never overwritten, even in a race
                    try:
                        os.link(tmp, self.path)
                    except FileExistsError:
                        raise OutputError(
                            f"{self.what} {str(self.path)!r} appeared while bwdesign worked; "
                            "not overwritten"
                        ) from None
                    os.unlink(tmp)
                else:
                    os.replace(tmp, self.path)
            except OSError as err:
                raise write_error(err, self.what, self.path) from None
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise

    def write_text(self, text: str) -> None:
        """Write the signature line and ``text``, atomically."""
        with self.open() as f:
            f.write(text)


def prepare_file(
    path: str | os.PathLike[str],
    *,
    command: str,
    comment: str | None = "#",
    what: str = "output file",
    exclusive: bool = False,
) -> FileTarget:
    """Check a single-file output before any work; refuse it with :class:`OutputError`.

    Parameters
    ----------
    path : path-like
    command : str
        The writer (``"simulate --csv"``), recorded in the signature line.
    comment : str or None
        Comment marker for the signature line (``"#"``, ``"//"``); None for
        formats without comments (an existing file is then always refused).
    what : str
        Name of the target in messages (``"--csv"``).
    exclusive : bool
        Refuse any existing file, even one bwdesign wrote (``bwdesign init``);
        the commit is then a hard link, which fails if the file appeared meanwhile.

    Returns
    -------
    FileTarget

    Raises
    ------
    OutputError
        The target is refused (see the module docstring); nothing was changed.
    """
    text = os.fspath(path)
    if not text.strip():
        raise OutputError(f"{what}: an empty path names no file; give a file name")
    target = Path(text)
    if text.endswith(("/", os.sep)) or target.name in ("", ".", ".."):
        raise OutputError(f"{what} {text!r} names a directory, not a file")
    parent = target.parent if str(target.parent) else Path(".")
    try:
        pst = os.stat(parent)
    except OSError:
        raise OutputError(f"{what} {text!r}: directory {str(parent)!r} does not exist") from None
    if not stat.S_ISDIR(pst.st_mode):
        raise OutputError(f"{what} {text!r}: {str(parent)!r} is not a directory")
    if not is_writable(pst, parent):
        raise OutputError(f"{what} {text!r}: directory {str(parent)!r} is not writable")
    st = lstat_or_none(target, what)
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            raise OutputError(
                f"{what} {text!r} is a symbolic link; give the file itself (bwdesign does not "
                "write through links)"
            )
        if not stat.S_ISREG(st.st_mode):
            raise OutputError(f"{what} {text!r} exists and is {kind_of(st)}, not a regular file")
        if exclusive:
            raise OutputError(
                f"{what} {text!r} already exists; not overwritten (choose another name)"
            )
        if not _writable_file(st, target):
            raise OutputError(f"{what} {text!r} is read-only; bwdesign does not replace it")
        if not _signed(target, command, comment):
            raise OutputError(
                f"{what} {text!r} exists and is not a file `bwdesign {command}` wrote (or was "
                "changed since); bwdesign never overwrites other files: choose another name "
                "or remove it yourself"
            )
    _clear_stale(target)
    return FileTarget(path=target, command=command, comment=comment, what=what, exclusive=exclusive)


def _writable_file(st: os.stat_result, path: Path) -> bool:
    return bool(st.st_mode & 0o222) and os.access(path, os.W_OK)


def _clear_stale(target: Path) -> None:
    """Remove temporaries of ``target`` left by killed runs (see :func:`.staging.leftover`)."""
    parent = target.parent if str(target.parent) else Path(".")
    try:
        names = os.listdir(parent)
    except OSError:
        return
    for name in names:
        owner = temporary_owner(name, target.name)
        if owner is not None and leftover(parent / name, owner):
            p = parent / name
            with contextlib.suppress(OSError):
                if stat.S_ISREG(os.lstat(p).st_mode):
                    os.unlink(p)
