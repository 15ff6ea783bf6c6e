"""Safe file output: the one layer through which every bwdesign command writes files.

No command ever deletes, moves or overwrites a file bwdesign did not write.
Targets are checked *before* any work is done; every write is atomic.

Directory outputs (``bwdesign report --out DIR``)::

    target = prepare_directory(out, command="report", force=False, what="--out")
    with target.stage() as stage:                 # refused targets raised OutputError above
        stage.write_text("report.md", text)       # files go to a staging directory
        save_figure(fig, stage.file("figures/a.png"))   # a path for any other writer
    # leaving the block normally commits; an exception (or a kill) leaves DIR as it was

- ``DIR`` may be missing (it is created, with missing parents), empty, or a
  directory bwdesign wrote for the same command before: such a directory holds
  a manifest ``.bwdesign-manifest.json`` (command, version, the relative paths
  written with their SHA-256). Anything else inside it (a file not in the
  manifest, a listed file changed since, a symlink, a FIFO, an empty
  directory, the manifest of another command) is *foreign*: the target is
  refused, naming one foreign path, unless ``force=True``; even then foreign
  files are kept untouched, only files of the previous manifest whose
  contents are unchanged (or changed, with ``force``) are replaced, and a new
  file that would land on a foreign path is refused.
- Refused before work: an empty path, the current directory, a symbolic link,
  anything that is not a directory, a directory (or nearest existing parent)
  that cannot be written (no write permission bit, so also when run as root).
- Work happens in a staging directory ``DIR/.bwdesign-tmp-<command>-<pid>-<hex>/``.
  A run that fails or is interrupted removes it (and ``DIR`` if the run
  created it); a run killed by SIGKILL leaves it behind, recognisable by its
  name, and the next run of the same command removes it (when no process with
  that pid is alive) before it starts; while that pid runs (or if an unrelated
  process reused it) the target is refused, naming the staging directory.
  The previous output is untouched until the commit.
- Commit (milliseconds, after all work): first a manifest marked
  ``"complete": false`` listing the old and new files (with both checksums),
  then each file moved into place with :func:`os.replace` (each move is
  atomic), then files of the previous run that this run did not write are
  deleted, then the final manifest replaces the pending one. A kill *during
  the commit* can leave a directory whose files come from two runs; the
  pending manifest still recognises all of them, so the next run replaces
  them without ``--force``. It never loses or damages a foreign file.

Single-file outputs (``bwdesign simulate --csv FILE``; stage TOML, C sources)::

    target = prepare_file(path, command="simulate --csv", what="--csv")
    ...                                            # the work
    target.write_text(body)                        # or: with target.open() as f: ...

- The first line written is the signature ``# written by bwdesign <version>
  (<command>) sha256=<hex>``, the checksum of everything after that line
  (``comment="//"`` for C; ``comment=None`` for formats without comments,
  whose existing files are then never replaced). An existing file is replaced
  only when it carries the signature of the same command and its checksum
  still matches: a user's file, or a bwdesign file the user edited, is never
  replaced (there is no ``force`` for single files: the user removes or
  renames their own file).
- Refused before work: an empty path, a directory, a symbolic link, a FIFO, a
  device or socket, a read-only file, a missing or unwritable parent directory.
- The file is written under ``.<name>.bwdesign-tmp-<pid>-<hex>`` beside the
  target, flushed, then moved over it with :func:`os.replace`; on any error
  the temporary is removed, and one left by a kill is removed by the next
  :func:`prepare_file` for the same path.

Written files get the mode the user's umask gives (created with ``0o666``,
directories ``0o777``, masked). Operating-system failures while writing (disk
full, permission) become :class:`~bwdesign.errors.OutputError` (a
``ValueError``) with the path and the reason; the CLI prints it as one
``error:`` line with exit 2.

Known limits: the checks and the final moves are separate system calls, so a
file another process creates at the same path in between can still be
replaced (the window is the commit phase). Hard links are not followed: a
replaced file that had other links leaves those links with the old contents.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import secrets
import shutil
import stat
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from .._version import __version__
from ..errors import OutputError

__all__ = [
    "MANIFEST",
    "STAGING_PREFIX",
    "DirectoryTarget",
    "FileTarget",
    "Stage",
    "prepare_directory",
    "prepare_file",
    "signature_line",
]

#: Name of the manifest a directory output holds.
MANIFEST = ".bwdesign-manifest.json"
#: Prefix of staging directories and temporary files.
STAGING_PREFIX = ".bwdesign-tmp-"
_STAGING = re.compile(r"^\.bwdesign-tmp-(?P<slug>[A-Za-z0-9-]+?)-(?P<pid>\d+)-[0-9a-f]+$")


def _slug(command: str) -> str:
    slug = re.sub(r"[^A-Za-z0-9]+", "-", command).strip("-")
    if not slug:
        raise ValueError(f"command must name the writer, got {command!r}")
    return slug


def _alive(pid: int) -> bool:
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


def _writable(st: os.stat_result, path: Path) -> bool:
    """Writable by us *and* carrying a write bit (root ignores the bits otherwise)."""
    return bool(st.st_mode & 0o222) and os.access(path, os.W_OK | os.X_OK)


def _kind(st: os.stat_result) -> str:
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


def _lstat(path: Path, what: str) -> os.stat_result | None:
    """``os.lstat`` or None when missing; other failures refuse the target."""
    try:
        return os.lstat(path)
    except FileNotFoundError:
        return None
    except NotADirectoryError:
        raise OutputError(f"{what} {str(path)!r}: a parent of it is not a directory") from None
    except OSError as err:
        raise OutputError(f"{what} {str(path)!r}: cannot inspect it ({err.strerror})") from None


def _check_parent(path: Path, what: str) -> None:
    """The nearest existing ancestor of ``path`` is a writable directory."""
    parent = Path(os.path.abspath(path)).parent
    while True:
        st = _lstat(parent, what)
        if st is not None:
            break
        parent = parent.parent
    try:
        st = os.stat(parent)  # symlinks above the target are fine (e.g. /tmp)
    except OSError as err:
        raise OutputError(f"{what} {str(path)!r}: cannot inspect {str(parent)!r}") from err
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{what} {str(path)!r}: {str(parent)!r} is not a directory")
    if not _writable(st, parent):
        raise OutputError(f"{what} {str(path)!r}: directory {str(parent)!r} is not writable")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _write_new(path: Path, data: bytes) -> None:
    """Create ``path`` (must not exist) with mode 0o666 & ~umask, write and flush it."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def _os_error(err: OSError, what: str, path: Path) -> OutputError:
    reason = err.strerror or str(err)
    return OutputError(f"{what} {str(path)!r}: cannot write ({reason}); nothing was replaced")


# -- directories ---------------------------------------------------------------


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
            raise ValueError(f"output path must be relative and inside the output: {relpath!r}")
        target = self.root / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        return target

    def write_text(self, relpath: str | Path, text: str) -> Path:
        """Write ``text`` (UTF-8) to ``relpath`` in the stage; returns its path."""
        return self.write_bytes(relpath, text.encode("utf-8"))

    def write_bytes(self, relpath: str | Path, data: bytes) -> Path:
        """Write ``data`` to ``relpath`` in the stage; returns its path."""
        path = self.file(relpath)
        _write_new(path, data)
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
        root = self.path / f"{STAGING_PREFIX}{_slug(self.command)}-{os.getpid()}-{token}"
        try:
            try:
                os.mkdir(root)
                yield Stage(root)
            except OSError as err:
                where = os.path.abspath(os.fsdecode(err.filename or ""))
                if not where.startswith(os.path.abspath(root) + os.sep):
                    raise  # not a write of this stage: the writer's own error
                raise _os_error(err, self.what, self.path) from None
            try:
                self._commit(root)
            except OSError as err:
                raise _os_error(err, self.what, self.path) from None
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
                raise _os_error(err, self.what, self.path) from None
        return list(reversed(missing))

    def _commit(self, root: Path) -> None:
        new: dict[str, str] = {}
        for dirpath, dirnames, filenames in os.walk(root):
            for name in dirnames + filenames:
                p = Path(dirpath) / name
                st = os.lstat(p)
                if stat.S_ISREG(st.st_mode):
                    new[p.relative_to(root).as_posix()] = _sha256(p)
                elif not stat.S_ISDIR(st.st_mode):
                    raise OutputError(f"{self.what}: the writer staged {_kind(st)} {name!r}")
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
            st = _lstat(self.path / parent, self.what)
            if st is not None and not stat.S_ISDIR(st.st_mode):
                raise OutputError(
                    f"{self.what} {str(self.path)!r}: {parent.as_posix()} is {_kind(st)} that "
                    f"bwdesign did not write, where it would write {rel}; nothing was replaced"
                )
        st = _lstat(self.path / rel, self.what)
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
        _write_new(tmp, (json.dumps(doc, indent=2) + "\n").encode("utf-8"))
        os.replace(tmp, self.path / MANIFEST)


def _read_manifest(path: Path, command: str, what: str) -> dict[str, list[str]] | None:
    """Files listed by ``path/MANIFEST`` (relative path -> checksums), None if absent."""
    mpath = path / MANIFEST
    st = _lstat(mpath, what)
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
    st = _lstat(target, what)
    if st is None:
        _check_parent(target, what)
        return DirectoryTarget(path=target, command=command, force=force, what=what)
    if stat.S_ISLNK(st.st_mode):
        raise OutputError(
            f"{what} {text!r} is a symbolic link; give the directory itself (bwdesign does not "
            "write through links)"
        )
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{what} {text!r} exists and is {_kind(st)}, not a directory")
    if not _writable(st, target):
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
    """Classify the directory's contents: replaceable previous files, foreign paths."""
    slug = _slug(command)
    previous: dict[str, bool] = {}
    foreign: list[str] = []
    for dirpath, dirnames, filenames in os.walk(target):
        here = Path(dirpath)
        if here == target:
            for name in list(dirnames):
                m = _STAGING.match(name)
                if m and m["slug"] == slug and not os.path.islink(here / name):
                    dirnames.remove(name)
                    if _alive(int(m["pid"])):
                        raise OutputError(
                            f"{what} {str(target)!r}: another `bwdesign {command}` (pid "
                            f"{m['pid']}) is writing into it; wait for it, or remove {name} "
                            "if no such run exists"
                        )
                    shutil.rmtree(here / name, ignore_errors=True)  # a killed run's stage
        if here != target and not dirnames and not filenames:
            rel = here.relative_to(target).as_posix()
            if not any(k.startswith(rel + "/") for k in listed):
                foreign.append(rel + "/")
        for name in dirnames + filenames:
            p = here / name
            rel = p.relative_to(target).as_posix()
            if rel == MANIFEST:
                continue
            st = os.lstat(p)
            if stat.S_ISDIR(st.st_mode):
                continue
            if rel in listed and stat.S_ISREG(st.st_mode):
                try:
                    unchanged = _sha256(p) in listed[rel]
                except OSError:
                    unchanged = False
                previous[rel] = unchanged
                if not unchanged:
                    foreign.append(f"{rel} (changed since bwdesign wrote it)")
            else:
                foreign.append(rel if stat.S_ISREG(st.st_mode) else f"{rel} ({_kind(st)})")
    return previous, sorted(foreign)


# -- single files -------------------------------------------------------------


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
        tmp = self.path.parent / f".{self.path.name}.bwdesign-tmp-{os.getpid()}-{token}"
        try:
            try:
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
                with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
                    if self.comment is not None:
                        f.write(signature_line(self.command, self.comment) + "\n")
                    yield f
                if self.comment is not None:
                    _fill_digest(tmp)
                st = _lstat(self.path, self.what)
                if st is not None and not stat.S_ISREG(st.st_mode):
                    raise OutputError(
                        f"{self.what} {str(self.path)!r} became {_kind(st)} while bwdesign "
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
                raise _os_error(err, self.what, self.path) from None
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
    if not _writable(pst, parent):
        raise OutputError(f"{what} {text!r}: directory {str(parent)!r} is not writable")
    st = _lstat(target, what)
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            raise OutputError(
                f"{what} {text!r} is a symbolic link; give the file itself (bwdesign does not "
                "write through links)"
            )
        if not stat.S_ISREG(st.st_mode):
            raise OutputError(f"{what} {text!r} exists and is {_kind(st)}, not a regular file")
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
    """Remove temporaries of ``target`` left by killed runs (their pid is gone)."""
    parent = target.parent if str(target.parent) else Path(".")
    pattern = re.compile(rf"^\.{re.escape(target.name)}\.bwdesign-tmp-(\d+)-[0-9a-f]+$")
    try:
        names = os.listdir(parent)
    except OSError:
        return
    for name in names:
        m = pattern.match(name)
        if m and not _alive(int(m[1])):
            p = parent / name
            with contextlib.suppress(OSError):
                if stat.S_ISREG(os.lstat(p).st_mode):
                    os.unlink(p)
