"""``bwdesign report --config FILE.toml --out DIR`` (registered in :mod:`bwdesign.cli.main`).

The command line becomes one frozen :class:`ReportRequest` (validated once); the
argparse namespace is read, never changed. Exit codes: 0 the report says
CERTIFIED; 1 it says no (not certified, synthesis infeasible, the reference needs
more input than the limits allow), the report is written; 2 bad input, one
``error:`` line and nothing written.

The study (and its figures) is read from the study cache when the same stage file
was reported before by the same code and libraries (:mod:`bwdesign.study.cache`,
in ``$BWDESIGN_CACHE_DIR``, else ``$XDG_CACHE_HOME/bwdesign``, else
``~/.cache/bwdesign``); ``--no-cache`` computes it (and keeps nothing). On a machine
with two cores or more a second process computes part of the study and draws half
the figures (:mod:`bwdesign.study.background`; the same report, sooner).
"""

from __future__ import annotations

import argparse
import os
from dataclasses import dataclass

from .args import EXIT_NO, EXIT_OK, UsageError

__all__ = ["ReportRequest", "report_args", "run_report"]


def report_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign report``."""
    p.add_argument(
        "--config",
        required=True,
        metavar="FILE.toml",
        help="stage configuration file, or a bundled preset's name (see bwdesign presets)",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="report directory: new, empty, or a report bwdesign wrote (its files are "
        "replaced); never the current directory",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="write into a directory holding other files (they are kept, never overwritten)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument(
        "--no-cache",
        action="store_true",
        help="compute the study even if it was kept in the study cache, and keep nothing "
        "(the cache: $BWDESIGN_CACHE_DIR, else $XDG_CACHE_HOME/bwdesign or ~/.cache/bwdesign)",
    )
    p.add_argument(
        "--allow-unbounded",
        action="store_true",
        help="accept parameters outside the bounded Bouc-Wen class",
    )


@dataclass(frozen=True)
class ReportRequest:
    """What ``bwdesign report`` was asked: the stage, the directory and the switches.

    Parameters
    ----------
    config : str
        A stage file or a bundled preset's name (resolved by
        :func:`bwdesign.model.config.load_config`).
    out : str
        The report directory, as given (checked by the output layer before any work).
    force, quiet, allow_unbounded : bool
    no_cache : bool
        Compute the study without the study cache (neither read nor kept).
    """

    config: str
    out: str
    force: bool = False
    quiet: bool = False
    allow_unbounded: bool = False
    no_cache: bool = False

    def __post_init__(self) -> None:
        for name in ("config", "out"):
            if not isinstance(getattr(self, name), str):
                raise UsageError(f"--{name} must be a path, got {getattr(self, name)!r}")
        for name in ("force", "quiet", "allow_unbounded", "no_cache"):
            if not isinstance(getattr(self, name), bool):
                raise UsageError(f"{name} must be true or false, got {getattr(self, name)!r}")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ReportRequest:
        """The request of parsed arguments (read only)."""
        return cls(
            config=args.config,
            out=args.out,
            force=args.force,
            quiet=args.quiet,
            allow_unbounded=args.allow_unbounded,
            no_cache=getattr(args, "no_cache", False),  # a namespace built by hand may lack it
        )


def run_report(args: argparse.Namespace) -> int:
    """Write the report :class:`ReportRequest` ``args`` asks for; print where and the verdict.

    The compiled batch kernels (the falsifier's and the baselines' runs) run in a process
    forked now, before numpy, scipy and the rest are imported (:mod:`bwdesign.sim.kernel_process`):
    numba's 160 MB stay out of this process, the results are the same.
    """
    from ..sim import kernel_process

    with kernel_process.running():
        return _report(args)


def _report(args: argparse.Namespace) -> int:
    from ..model.config import load_config
    from ..output.files import prepare_directory
    from ..report.certified import write_report
    from ..study.cache import StudyCache

    req = ReportRequest.from_args(args)
    # --out is checked before the stage file is read: a bad directory is said first
    prepare_directory(req.out, command="report", force=req.force, what="--out")
    outcome = write_report(
        load_config(req.config),
        req.out,
        quiet=req.quiet,
        allow_unbounded=req.allow_unbounded,
        force=req.force,
        cache=None if req.no_cache else StudyCache(),
        workers=min(2, os.cpu_count() or 1),
    )
    print(f"{outcome.out_dir}/report.md: {outcome.verdict}")
    return EXIT_OK if outcome.certified else EXIT_NO
