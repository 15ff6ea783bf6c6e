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
  file that would land on a foreign path is refused. Only ``DIR``'s top level
  and the directories the manifest's own paths pass through are listed: any
  other directory is one foreign entry, never entered (``--out /`` lists
  ``/`` alone), and an entry that vanishes while it is looked at is gone.
- Refused before work: an empty path, the current directory, a symbolic link,
  anything that is not a directory, a directory (or nearest existing parent)
  that cannot be written (no write permission bit, so also when run as root).
- Work happens in a staging directory ``DIR/.bwdesign-tmp-<command>-<pid>@<host>-<hex>/``.
  A run that fails or is interrupted removes it (and ``DIR`` if the run
  created it); a run killed by SIGKILL leaves it behind, recognisable by its
  name, and the next run of the same command removes it before it starts when
  it was written on this host by a pid that no longer runs, or is 24 h old
  (:mod:`.staging`); otherwise (that pid runs, an unrelated process reused
  it, or the run is on another host sharing the folder) the target is
  refused, naming the staging directory and its owner.
  The previous output is untouched until the commit, and there is no commit
  once the command line recorded a Ctrl-C (:func:`bwdesign.interrupts.check`),
  even if a library caught the KeyboardInterrupt.
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
- The file is written under ``.<name>.bwdesign-tmp-<pid>@<host>-<hex>`` beside
  the target, flushed, then moved over it with :func:`os.replace`; on any error
  the temporary is removed, and one left by a kill is removed by the next
  :func:`prepare_file` for the same path (by the same rule as staging
  directories: this host and a dead pid, or 24 h old).

Written files get the mode the user's umask gives (created with ``0o666``,
directories ``0o777``, masked). Operating-system failures while writing (disk
full, permission) become :class:`~bwdesign.errors.OutputError` (a
``ValueError``) with the path and the reason; the CLI prints it as one
``error:`` line with exit 2.

Known limits: the checks and the final moves are separate system calls, so a
file another process creates at the same path in between can still be
replaced (the window is the commit phase). Hard links are not followed: a
replaced file that had other links leaves those links with the old contents.

The result cache (:mod:`.cache`, :class:`ResultCache`) is the one place bwdesign
keeps files between runs that are not a command's output: entries in a cache folder
(never an output directory), written atomically, and a damaged entry is a miss.
"""

from .cache import ResultCache, default_cache_dir
from .common import MANIFEST
from .directory import DirectoryTarget, Stage, prepare_directory
from .single import FileTarget, prepare_file, signature_line
from .staging import STAGING_PREFIX

__all__ = [
    "MANIFEST",
    "STAGING_PREFIX",
    "DirectoryTarget",
    "FileTarget",
    "ResultCache",
    "Stage",
    "default_cache_dir",
    "prepare_directory",
    "prepare_file",
    "signature_line",
]
