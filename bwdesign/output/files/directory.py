"""Directory outputs: a manifest, a staging directory, the commit (see the package docstring)."""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import shutil
import stat
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from ... import interrupts
from ..._version import __version__
from ...errors import OutputError
from .common import (
    MANIFEST,
    check_parent,
    command_slug,
    is_writable,
    kind_of,
    lstat_or_none,
    sha256_of,
    write_error,
    write_new,
)
from .staging import STALE_AFTER_S, leftover, staging_name, staging_owner

__all__ = ["DirectoryTarget", "Stage", "prepare_directory"]


@dataclass(frozen=True)
class Stage:
    """The staging directory of one run; every output file is written inside it.

    Attributes
    ----------
    root : Path
        The staging directory (inside the target); writers that build a tree
        themselves may write anywhere below it.
    """

    root: Path

    def file(self, relpath: str | Path) -> Path:
        """A path inside the stage for ``relpath`` (parents created), for any writer."""
        rel = Path(relpath)
        if rel.is_absolute() or ".." in rel.parts or not rel.parts:
            raise OutputError(f"output path must be relative and inside the output: {relpath!r}")
        target = self.root / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        return target

    def write_text(self, relpath: str | Path, text: str) -> Path:
        """Write ``text`` (UTF-8) to ``relpath`` in the stage; returns its path."""
        return self.write_bytes(relpath, text.encode("utf-8"))

    def write_bytes(self, relpath: str | Path, data: bytes) -> Path:
        """Write ``data`` to ``relpath`` in the stage; returns its path."""
        path = self.file(relpath)
        write_new(path, data)
        return path


@dataclass(frozen=True)
class DirectoryTarget:
    """A directory output checked by :func:`prepare_directory`; write it with :meth:`stage`.

    Attributes
    ----------
    path : Path
    command : str
        The writer (``"report"``); the manifest records it.
    force : bool
        Write beside foreign files (never over them).
    what : str
        How messages name the target (``"--out"``).
    previous : dict
        Files of the previous manifest that may be replaced: relative path ->
        True when unchanged since bwdesign wrote it (then also deleted if this
        run does not write it again), False when changed (replaced only with
        ``force``, never deleted).
    previous_hashes : dict
        Relative path -> checksums recorded by the previous manifest.
    """

    path: Path
    command: str
    force: bool = False
    what: str = "output directory"
    previous: dict[str, bool] = field(default_factory=dict)
    previous_hashes: dict[str, list[str]] = field(default_factory=dict)

    @contextlib.contextmanager
    def stage(self) -> Iterator[Stage]:
        """Stage the run's files, then commit them (see the module docstring).

        Raises
        ------
        OutputError
            The operating system refused a write, or a new file would land on
            a foreign path; the previous output is then unchanged.
        """
        created = self._make_dirs()
        token = secrets.token_hex(4)
        root = self.path / staging_name(command_slug(self.command), token)
        try:
            try:
                os.mkdir(root)
                yield Stage(root)
            except OSError as err:
                where = os.path.abspath(os.fsdecode(err.filename or ""))
                if not where.startswith(os.path.abspath(root) + os.sep):
                    raise  # not a write of this stage: the writer's own error
                raise write_error(err, self.what, self.path) from None
            interrupts.check()  # a Ctrl-C something swallowed: the previous output stays
            try:
                self._commit(root)
            except OSError as err:
                raise write_error(err, self.what, self.path) from None
        except BaseException:
            shutil.rmtree(root, ignore_errors=True)
            for d in reversed(created):
                with contextlib.suppress(OSError):
                    os.rmdir(d)
            raise
        shutil.rmtree(root, ignore_errors=True)

    def _make_dirs(self) -> list[Path]:
        missing = []
        p = Path(os.path.abspath(self.path))
        while not os.path.lexists(p):
            missing.append(p)
            p = p.parent
        for d in reversed(missing):
            try:
                os.mkdir(d)
            except OSError as err:
                raise write_error(err, self.what, self.path) from None
        return list(reversed(missing))

    def _commit(self, root: Path) -> None:
        new: dict[str, str] = {}
        for dirpath, dirnames, filenames in os.walk(root):
            for name in dirnames + filenames:
                p = Path(dirpath) / name
                st = os.lstat(p)
                if stat.S_ISREG(st.st_mode):
                    new[p.relative_to(root).as_posix()] = sha256_of(p)
                elif not stat.S_ISDIR(st.st_mode):
                    raise OutputError(f"{self.what}: the writer staged {kind_of(st)} {name!r}")
        if MANIFEST in new:
            raise OutputError(f"{self.what}: a writer may not write {MANIFEST}")
        for rel in sorted(new):
            self._check_destination(rel)
        pending = {k: list(v) for k, v in self.previous_hashes.items() if k in self.previous}
        for rel, h in new.items():
            pending[rel] = sorted(set(pending.get(rel, [])) | {h})
        self._write_manifest(root, pending, complete=False)
        for rel in sorted(new):
            dest = self.path / rel
            for parent in reversed(Path(rel).parents[:-1]):
                d = self.path / parent
                if not os.path.lexists(d):
                    os.mkdir(d)
            os.replace(root / rel, dest)
        for rel, unchanged in sorted(self.previous.items()):
            if rel in new or not unchanged:
                continue
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.path / rel)
            for parent in Path(rel).parents[:-1]:
                with contextlib.suppress(OSError):
                    os.rmdir(self.path / parent)  # only when empty
        self._write_manifest(root, {k: [v] for k, v in new.items()}, complete=True)

    def _check_destination(self, rel: str) -> None:
        for parent in reversed(Path(rel).parents[:-1]):
            st = lstat_or_none(self.path / parent, self.what)
            if st is not None and not stat.S_ISDIR(st.st_mode):
                raise OutputError(
                    f"{self.what} {str(self.path)!r}: {parent.as_posix()} is {kind_of(st)} that "
                    f"bwdesign did not write, where it would write {rel}; nothing was replaced"
                )
        st = lstat_or_none(self.path / rel, self.what)
        if st is None:
            return
        if rel not in self.previous or not stat.S_ISREG(st.st_mode):
            raise OutputError(
                f"{self.what} {str(self.path)!r}: bwdesign would overwrite {rel}, which it did "
                "not write; nothing was replaced (move that file away or choose another "
                "directory)"
            )

    def _write_manifest(self, root: Path, files: dict[str, list[str]], *, complete: bool) -> None:
        doc = {
            "written_by": "bwdesign",
            "version": __version__,
            "command": self.command,
            "complete": complete,
            "files": dict(sorted(files.items())),
        }
        tmp = root / f"manifest-{secrets.token_hex(4)}.json"
        write_new(tmp, (json.dumps(doc, indent=2) + "\n").encode("utf-8"))
        os.replace(tmp, self.path / MANIFEST)


def _read_manifest(path: Path, command: str, what: str) -> dict[str, list[str]] | None:
    """Files listed by ``path/MANIFEST`` (relative path -> checksums), None if absent."""
    mpath = path / MANIFEST
    st = lstat_or_none(mpath, what)
    if st is None:
        return None
    foreign = OutputError(
        f"{what} {str(path)!r} holds {MANIFEST}, which is not a bwdesign manifest; "
        "choose another directory"
    )
    if not stat.S_ISREG(st.st_mode) or st.st_size > 1 << 22:
        raise foreign
    try:
        doc = json.loads(mpath.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        raise foreign from None
    if not isinstance(doc, dict):
        raise foreign
    files = doc.get("files")
    if (
        doc.get("written_by") != "bwdesign"
        or not isinstance(files, dict)
        or not all(
            isinstance(k, str)
            and isinstance(v, list)
            and all(isinstance(h, str) for h in v)
            and not Path(k).is_absolute()
            and ".." not in Path(k).parts
            for k, v in files.items()
        )
    ):
        raise foreign
    if doc.get("command") != command:
        raise OutputError(
            f"{what} {str(path)!r} was written by `bwdesign {doc.get('command')}`, not "
            f"`bwdesign {command}`; choose another directory"
        )
    return files


def prepare_directory(
    path: str | os.PathLike[str],
    *,
    command: str,
    force: bool = False,
    what: str = "output directory",
    expect: tuple[str, ...] = (),
) -> DirectoryTarget:
    """Check a directory output before any work; refuse it with :class:`OutputError`.

    Parameters
    ----------
    path : path-like
        The output directory (created when missing).
    command : str
        The writing command (``"report"``): only a directory whose manifest
        names the same command is replaced.
    force : bool
        Accept a directory holding foreign files: write beside them, never
        over them.
    what : str
        Name of the target in messages (the option, e.g. ``"--out"``).
    expect : tuple of str
        Relative paths the run will write, if known: a foreign file at one of
        them is refused now rather than at the commit.

    Returns
    -------
    DirectoryTarget
        Write it with :meth:`DirectoryTarget.stage`.

    Raises
    ------
    OutputError
        The target is refused (see the module docstring); nothing was changed.
    """
    text = os.fspath(path)
    if not text.strip():
        raise OutputError(f"{what}: an empty path names no directory; give a directory name")
    target = Path(text)
    if os.path.abspath(text) == os.getcwd():
        raise OutputError(
            f"{what} {text!r} is the current directory; give a new or bwdesign-written directory"
        )
    st = lstat_or_none(target, what)
    if st is None:
        check_parent(target, what)
        return DirectoryTarget(path=target, command=command, force=force, what=what)
    if stat.S_ISLNK(st.st_mode):
        raise OutputError(
            f"{what} {text!r} is a symbolic link; give the directory itself (bwdesign does not "
            "write through links)"
        )
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{what} {text!r} exists and is {kind_of(st)}, not a directory")
    if not is_writable(st, target):
        raise OutputError(f"{what} {text!r} is not writable")
    listed = _read_manifest(target, command, what) or {}
    previous, foreign = _scan(target, command, listed, what)
    if foreign and not force:
        more = f" (and {len(foreign) - 1} more)" if len(foreign) > 1 else ""
        raise OutputError(
            f"{what} {text!r} holds {foreign[0]}{more}, which bwdesign did not write; "
            "bwdesign never deletes, moves or overwrites "
            "other files: choose a new or empty directory, or pass --force to write beside "
            "them (they are kept)"
        )
    if not force:
        previous = {k: v for k, v in previous.items() if v}
    out = DirectoryTarget(
        path=target,
        command=command,
        force=force,
        what=what,
        previous=previous,
        previous_hashes=listed,
    )
    for rel in expect:
        out._check_destination(rel)
    return out


def _scan(
    target: Path, command: str, listed: dict[str, list[str]], what: str
) -> tuple[dict[str, bool], list[str]]:
    """Classify the directory's contents: replaceable previous files, foreign paths.

    Lists the target's top level and the directories the manifest's own paths
    pass through, nothing else: any other directory is one foreign entry,
    never entered (``--out /`` lists ``/`` only). An entry that vanishes while
    it is looked at (another process's temporary file) is gone, not an error.
    """
    own_dirs = {p.as_posix() for rel in listed for p in PurePosixPath(rel).parents[:-1]}
    previous: dict[str, bool] = {}
    foreign: list[str] = []
    pending = [""]
    while pending:
        rel_dir = pending.pop()
        here = target / rel_dir
        try:
            names = os.listdir(here)
        except (FileNotFoundError, NotADirectoryError):
            continue  # gone (or replaced) since it was seen: nothing of it to keep
        except OSError as err:
            raise OutputError(
                f"{what} {str(target)!r}: cannot list {rel_dir or '.'} ({err.strerror})"
            ) from None
        for name in names:
            rel = f"{rel_dir}/{name}" if rel_dir else name
            if rel == MANIFEST or (not rel_dir and _own_staging(target / name, command, what)):
                continue
            st = lstat_or_none(here / name, what)
            if st is None:
                continue  # vanished during the scan
            if stat.S_ISDIR(st.st_mode):
                if rel in own_dirs:
                    pending.append(rel)
                else:
                    foreign.append(rel + "/")
            elif rel in listed and stat.S_ISREG(st.st_mode):
                try:
                    unchanged = sha256_of(here / name) in listed[rel]
                except FileNotFoundError:
                    continue  # vanished during the scan
                except OSError:
                    unchanged = False
                previous[rel] = unchanged
                if not unchanged:
                    foreign.append(f"{rel} (changed since bwdesign wrote it)")
            else:
                foreign.append(rel if stat.S_ISREG(st.st_mode) else f"{rel} ({kind_of(st)})")
    return previous, sorted(foreign)


def _own_staging(path: Path, command: str, what: str) -> bool:
    """``path`` is a staging directory of this command: removed if its run is gone.

    Raises :class:`OutputError` while its run may still be writing (see
    :mod:`.staging`: another host's run is kept until the stated age).
    """
    owner = staging_owner(path.name, command_slug(command))
    if owner is None:
        return False
    st = lstat_or_none(path, what)
    if st is None:
        return True  # vanished
    if not stat.S_ISDIR(st.st_mode):
        return False  # a link or file under such a name is not ours: foreign
    if leftover(path, owner):
        shutil.rmtree(path, ignore_errors=True)  # a killed run's stage
        return True
    hours = STALE_AFTER_S / 3600
    raise OutputError(
        f"{what} {str(path.parent)!r}: another `bwdesign {command}` ({owner.describe()}) may be "
        f"writing into it; wait for it, or remove {path.name} if no such run exists "
        f"(bwdesign removes it itself once it is {hours:g} h old)"
    )
