"""``bwdesign export-c`` (registered in :mod:`bwdesign.cli.main`).

Exit codes: 0 written; 1 nothing certifies the gains (nothing written unless
``--allow-uncertified``); 2 bad input with one ``error:`` line, nothing written.

``--controller pi|pid|pi-bwff|pi-piff`` exports a baseline instead (no observer,
:mod:`bwdesign.codegen.baselines`): with the stage's ``[baseline]`` gains when its kind
is the one asked, else tuned by the phase-margin rule; exit 1 (files written) when its
nominal linear loop is not stable.
"""

from __future__ import annotations

import argparse

from ..codegen.baselines import export_baseline_c
from ..codegen.export import OBSERVERS, export_c
from ..codegen.literals import PRECISIONS
from ..model.config import BASELINE_KINDS, load_config
from ..output.jsonenc import dump_json
from .args import EXIT_NO, EXIT_OK, UsageError

__all__ = ["export_c_args", "run_export_c"]


def export_c_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign export-c``."""
    p.add_argument("--config", required=True, metavar="STAGE.toml", help="stage configuration")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory for the C files")
    p.add_argument("--precision", choices=PRECISIONS, default="float64", help="C arithmetic")
    p.add_argument(
        "--observer",
        choices=tuple(OBSERVERS),
        default="phso",
        help="the observer the harness runs by default (the library carries all three: phso, "
        "eso and phdo, the disturbance hysteresis observer); default phso",
    )
    p.add_argument("--prefix", default="bw", metavar="NAME", help="C name prefix (default bw)")
    p.add_argument(
        "--controller",
        choices=("eq12", *BASELINE_KINDS),
        default="eq12",
        help="eq12 (default): the observers and eq. (12); pi, pid, pi-bwff, pi-piff: that "
        "baseline (no observer; [baseline] gains when its kind matches, else the tuning rule)",
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument(
        "--synthesize",
        action="store_true",
        help="export gains synthesised for the config's envelope instead of [observer] gains",
    )
    src.add_argument(
        "--tuning",
        choices=("digital",),
        default=None,
        help="export the digital tuning's observer gains and controller constants",
    )
    p.add_argument(
        "--allow-uncertified",
        action="store_true",
        help="export gains that no certificate tier holds for (the header says so)",
    )
    p.add_argument(
        "--allow-unbounded",
        action="store_true",
        help="accept parameters outside the bounded Bouc-Wen class",
    )
    p.add_argument("--force", action="store_true", help="replace files bwdesign wrote before")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")


def _run_baseline(args: argparse.Namespace) -> int:
    given = [o for o, v in (("--synthesize", args.synthesize), ("--tuning", args.tuning)) if v]
    given += ["--allow-uncertified"] if args.allow_uncertified else []
    if given:
        raise UsageError(
            f"--controller {args.controller} exports a baseline (no observer, no certificate): "
            f"drop {', '.join(given)}"
        )
    config = load_config(args.config)
    spec = config.baseline if config.baseline and config.baseline["kind"] == args.controller else {}
    res = export_baseline_c(
        config,
        args.out,
        args.controller,
        precision=args.precision,
        prefix=args.prefix,
        gains=spec.get("gains"),
        phase_margin=spec.get("phase_margin", 60.0),
        delay=spec.get("delay", False),
        allow_unbounded=args.allow_unbounded,
        force=args.force,
    )
    if args.json:
        print(dump_json({"out_dir": str(res.out_dir), "files": list(res.files), **res.document}))
    else:
        stable = "stable" if res.certified else "NOT STABLE"
        print(f"{res.out_dir}: {', '.join(res.files)} ({args.precision}); {args.controller} "
              f"baseline, nominal linear loop {stable}")  # fmt: skip
        print(f"  build and check: cc -std=c99 -O2 {res.out_dir}/*.c -lm -o harness")
    return EXIT_OK if res.certified else EXIT_NO


def run_export_c(args: argparse.Namespace) -> int:
    if args.controller != "eq12":
        return _run_baseline(args)
    gains_from = "synthesize" if args.synthesize else ("digital" if args.tuning else "config")
    res = export_c(
        load_config(args.config),
        args.out,
        precision=args.precision,
        observer=args.observer,
        prefix=args.prefix,
        gains_from=gains_from,
        allow_uncertified=args.allow_uncertified,
        allow_unbounded=args.allow_unbounded,
        force=args.force,
    )
    if args.json:
        print(dump_json({"out_dir": str(res.out_dir), "files": list(res.files), **res.document}))
        return EXIT_OK
    s, d = res.summary, res.summary["phdo"]
    status = (
        f"PHSO/ESO gains certified by the {s['tier']} tier"
        if s["tier"] is not None
        else "PHSO/ESO gains NOT CERTIFIED"
    ) + (
        f", PHDO lumped error by the {d['tier']} tier of certify_disturbance"
        if d["certified"]
        else ", PHDO lumped error NOT CERTIFIED"
    )
    status += f" for |u'| <= {s['udot_max']:.6g} V/s" + (
        "" if res.certified else " (exported with --allow-uncertified)"
    )
    print(f"{res.out_dir}: {', '.join(res.files)} ({args.precision}); {status}")
    print(f"  build and check: cc -std=c99 -O2 {res.out_dir}/*.c -lm -o harness")
    return EXIT_OK
