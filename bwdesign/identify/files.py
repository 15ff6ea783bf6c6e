"""The one place identification writes files (until the package's output layer lands).

Atomic: the text goes to a temporary file in the target's directory, then
``os.replace``. An existing file is replaced only if bwdesign wrote it (its
first line carries a bwdesign signature); anything else is refused, so a
user's own file is never overwritten.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ..errors import InputError

__all__ = ["write_file", "SIGNATURE", "is_ours"]

#: First line of every text file identification writes (after the comment mark).
SIGNATURE = "written by bwdesign"
_MARKS = ("# ", "<!-- ")


def is_ours(path: Path) -> bool:
    """Does the existing file at ``path`` start with a bwdesign signature line?"""
    try:
        with open(path, "rb") as fh:
            head = fh.read(200).decode("utf-8", errors="replace")
    except OSError:
        return False
    return any(head.startswith(m + SIGNATURE) for m in _MARKS)


def write_file(path: str | Path, data: str | bytes, *, replace_foreign: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically.

    Parameters
    ----------
    path : str or Path
    data : str or bytes
        Text (UTF-8) or bytes.
    replace_foreign : bool
        Allow replacing an existing file without the signature (only for
        binary files inside a directory whose report bwdesign wrote).

    Raises
    ------
    InputError
        The target exists and bwdesign did not write it, or it cannot be written.
    """
    path = Path(path)
    if path.exists() and not replace_foreign and not is_ours(path):
        raise InputError(
            f"{path} exists and was not written by bwdesign; refusing to replace it "
            "(choose another path or remove it)"
        )
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data.encode("utf-8") if isinstance(data, str) else data)
            os.replace(tmp, path)
        except BaseException:
            os.unlink(tmp)
            raise
    except OSError as err:
        raise InputError(f"cannot write {path}: {err.strerror or err}") from None
    return path
