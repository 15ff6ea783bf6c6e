"""``bwdesign check FILE.toml...`` (registered in :mod:`bwdesign.cli.main`).

Runs every requirement of every file's ``[requirements]`` section and prints one
line per requirement. Exit codes: 0 all pass; 1 one fails (observer gains that are
not Hurwitz included: every requirement on them fails); 2 bad input (a file that
cannot be read, a malformed section, a requirement whose section is missing), and
then ``--junit-xml`` is not written (the other files' lines are still printed).
"""

from __future__ import annotations

import argparse
import sys

from ..errors import BWDesignError
from ..output.files import prepare_file
from ..output.jsonenc import dump_json
from ..testing.checks import check_requirements
from ..testing.junit import junit_xml
from .args import EXIT_BAD_INPUT, EXIT_NO, EXIT_OK

__all__ = ["check_args", "run_check"]


def check_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign check``."""
    p.add_argument("files", nargs="+", metavar="FILE.toml", help="stage files (or presets)")
    p.add_argument(
        "--junit-xml", metavar="PATH", default=None, help="write a JUnit XML report (not on exit 2)"
    )
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")


def run_check(args: argparse.Namespace) -> int:
    junit = None
    if args.junit_xml is not None:
        junit = prepare_file(
            args.junit_xml, command="check junit", comment="<!--", what="--junit-xml"
        )
    results = []
    bad = False
    for f in args.files:
        try:
            results.append((f, check_requirements(f)))
        except BWDesignError as err:
            # a file that cannot be checked is bad input; the others are still run
            results.append((f, " ".join(str(err).split())))
            bad = True
    failed = any(isinstance(c, list) and not all(x.passed for x in c) for _, c in results)
    if junit is not None and not bad:  # exit 2 writes nothing
        junit.write_text(junit_xml(results))
    if args.json:
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
