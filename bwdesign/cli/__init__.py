"""Command line: ``bwdesign SUBCOMMAND`` (also ``python -m bwdesign``). Nothing imports this
package.

:func:`main` is the program (the console script ``bwdesign`` and ``python -m
bwdesign``): :func:`bwdesign.cli.main.main`, after which SIGINT is ignored
while the process exits, so a late Ctrl-C prints no traceback. The imports
before it are light (the package ``bwdesign`` loads its API on first use).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from . import main as _commands

#: Thread-count variables of the BLAS/OpenMP runtimes numpy and scipy may load.
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread() -> None:
    """One BLAS thread for this process unless the user chose otherwise (set before numpy loads).

    Every matrix bwdesign factorises is small (3x3 to a few dozen rows): a BLAS thread
    pool only adds hand-offs, and on shared cores a 6x6 triangular solve took 7.9 ms with
    OpenBLAS's threads against 21 us without (a report 1.5x slower); the bundled reports
    are byte for byte the same either way. Dask's worker processes inherit the setting.
    """
    for var in BLAS_THREADS:
        os.environ.setdefault(var, "1")


def main(argv: Sequence[str] | None = None) -> int:
    """The ``bwdesign`` program; returns the exit code (130 after Ctrl-C)."""
    one_blas_thread()
    try:
        return _commands.main(argv, then_ignore_sigint=True)
    except KeyboardInterrupt:  # before the handler was installed
        return _commands.interrupted()


__all__ = ["main"]
