"""``bwdesign check FILE.toml...`` (registered in :mod:`bwdesign.cli.main`).

Runs every requirement of every file's ``[requirements]`` section and prints one
line per requirement. Exit codes: 0 all pass; 1 one fails (observer gains that are
not Hurwitz included: every requirement on them fails); 2 bad input (a file that
cannot be read, a malformed section, a requirement whose section is missing), and
then ``--junit-xml`` is not written (the other files' lines are still printed).

The command line becomes one frozen :class:`CheckRequest` (validated once); the
argparse namespace is read, never changed. Each file's requirements are read from
one study of it (:func:`bwdesign.testing.checks.check_requirements`), read from the
study cache when kept there (:mod:`bwdesign.study.cache`; ``--no-cache`` computes it).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass

from ..errors import BWDesignError
from ..output.files import prepare_file
from ..output.jsonenc import dump_json
from ..study.cache import StudyCache
from ..testing.checks import check_requirements
from ..testing.junit import junit_xml
from .args import EXIT_BAD_INPUT, EXIT_NO, EXIT_OK, UsageError

__all__ = ["CheckRequest", "check_args", "run_check"]


def check_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign check``."""
    p.add_argument("files", nargs="+", metavar="FILE.toml", help="stage files (or presets)")
    p.add_argument(
        "--junit-xml", metavar="PATH", default=None, help="write a JUnit XML report (not on exit 2)"
    )
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument(
        "--no-cache",
        action="store_true",
        help="compute each study even if it was kept in the study cache, and keep nothing",
    )


@dataclass(frozen=True)
class CheckRequest:
    """What ``bwdesign check`` was asked.

    Parameters
    ----------
    files : tuple of str
        Stage files or bundled presets' names, in the order given (at least one).
    junit_xml : str, optional
        Where to write the JUnit XML report.
    json : bool
        Print one JSON document instead of one line per requirement.
    no_cache : bool
        Compute the studies without the study cache (neither read nor kept).
    """

    files: tuple[str, ...]
    junit_xml: str | None = None
    json: bool = False
    no_cache: bool = False

    def __post_init__(self) -> None:
        files = self.files
        if isinstance(files, str) or not all(isinstance(f, str) for f in files):
            raise UsageError(f"files must be a sequence of paths, got {files!r}")
        object.__setattr__(self, "files", tuple(files))
        if not self.files:
            raise UsageError("check needs at least one stage file")
        if self.junit_xml is not None and not isinstance(self.junit_xml, str):
            raise UsageError(f"--junit-xml must be a path, got {self.junit_xml!r}")
        if not isinstance(self.json, bool):
            raise UsageError(f"json must be true or false, got {self.json!r}")
        if not isinstance(self.no_cache, bool):
            raise UsageError(f"no_cache must be true or false, got {self.no_cache!r}")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> CheckRequest:
        """The request of parsed arguments (read only)."""
        return cls(
            files=tuple(args.files),
            junit_xml=args.junit_xml,
            json=args.json,
            no_cache=getattr(args, "no_cache", False),  # a namespace built by hand may lack it
        )


def run_check(args: argparse.Namespace) -> int:
    """Check every file the :class:`CheckRequest` ``args`` names; print, exit 0, 1 or 2."""
    req = CheckRequest.from_args(args)
    junit = None
    if req.junit_xml is not None:
        junit = prepare_file(
            req.junit_xml, command="check junit", comment="<!--", what="--junit-xml"
        )
    results = []
    bad = False
    cache = None if req.no_cache else StudyCache()
    for f in req.files:
        try:
            results.append((f, check_requirements(f, cache=cache)))
        except BWDesignError as err:
            # a file that cannot be checked is bad input; the others are still run
            results.append((f, " ".join(str(err).split())))
            bad = True
    failed = any(isinstance(c, list) and not all(x.passed for x in c) for _, c in results)
    if junit is not None and not bad:  # exit 2 writes nothing
        junit.write_text(junit_xml(results))
    if req.json:
        print(
            dump_json(
                {
                    "files": [
                        {"file": f, "error": c}
                        if isinstance(c, str)
                        else {
                            "file": f,
                            "checks": [
                                {
                                    "name": x.name,
                                    "passed": x.passed,
                                    "value": x.value,
                                    "limit": x.limit,
                                    "text": x.text,
                                }
                                for x in c
                            ],
                        }
                        for f, c in results
                    ]
                }
            )
        )
    else:
        for _, checks in results:
            if isinstance(checks, str):
                continue
            for c in checks:
                print(c.line())
    for _, checks in results:
        if isinstance(checks, str):
            print(f"error: {checks}", file=sys.stderr)
    if bad:
        return EXIT_BAD_INPUT
    return EXIT_NO if failed else EXIT_OK
