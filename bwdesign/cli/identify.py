"""``bwdesign identify``: a measured record in, a stage TOML (and a report) out.

Exit codes: 0 fitted; 1 the fit did not converge (the reason, what would help and
the best fit found on stderr, nothing written); 2 bad input with one ``error:`` line
(nothing written).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..identify import identify, load_data
from ..identify.result import Z95
from ..identify.stagefile import stage_toml
from ..output.files import prepare_directory, prepare_file
from ..output.jsonenc import dump_json
from .args import EXIT_NO, EXIT_OK, UsageError

__all__ = ["identify_args", "run_identify"]


def identify_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign identify``."""
    p.add_argument(
        "--data",
        required=True,
        action="append",
        metavar="TRAIN.csv",
        help="training record (.csv/.npz); repeat it to fit several records together (any "
        "amplitudes and sample rates: one parameter set, an offset and initial state each)",
    )
    p.add_argument(
        "--validate",
        action="append",
        metavar="VALID.csv",
        help="held-out record for the fit percent (may be repeated)",
    )
    p.add_argument(
        "--columns", metavar="T,U,Y", help="names of the time, input, output columns (t,u,y)"
    )
    p.add_argument("--init", metavar="PRESET_OR_TOML", help="start (and prior) parameters")
    p.add_argument(
        "--fixed", metavar="NAMES", help="comma-separated parameters held at --init (e.g. a1,a2)"
    )
    p.add_argument("--multistart", type=int, default=3, metavar="N", help="refinements (3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the multistart perturbations")
    p.add_argument(
        "--max-nfev", type=int, default=200, metavar="N", help="evaluations per refinement (200)"
    )
    p.add_argument("--name", help="plant name in the stage file (default: the data file's stem)")
    p.add_argument("--out", required=True, metavar="STAGE.toml", help="stage file to write")
    p.add_argument("--report", metavar="DIR", help="write the identification report here")
    p.add_argument(
        "--force",
        action="store_true",
        help="with --report: write into a directory holding other files (they are kept, never "
        "overwritten), as report --force",
    )
    p.add_argument(
        "--form",
        choices=("piezo", "structural"),
        default="piezo",
        help="model form: piezo (default) or structural "
        '(README.md, section "The structural Bouc-Wen form")',
    )
    p.add_argument(
        "--periodic",
        action="store_true",
        help="--form structural: every record is one period of a periodic input (fitted and "
        "scored in the periodic steady state)",
    )
    p.add_argument(
        "--units",
        default="m,N",
        metavar="LENGTH,INPUT",
        help="--form structural: the records' length and input units (m,N)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


def run_identify(args: argparse.Namespace) -> int:
    """Run ``bwdesign identify``."""
    if args.form == "structural":
        from .identify_structural import run_identify_structural

        return run_identify_structural(args)
    if args.periodic or args.units != "m,N":
        raise UsageError("--periodic and --units apply to --form structural only")
    out = Path(args.out)
    if out.suffix.lower() != ".toml":
        raise UsageError(f"--out must be a .toml file, got {args.out!r}")
    if args.multistart < 1 or args.max_nfev < 1:
        raise UsageError("--multistart and --max-nfev must be >= 1")
    target = prepare_file(out, command="identify", what="--out")
    if args.force and not args.report:
        raise UsageError("--force applies to --report DIR only (a stage file is never overwritten)")
    report = None
    if args.report:
        report = prepare_directory(
            args.report, command="identify --report", force=args.force, what="--report"
        )
    data = [load_data(path, columns=args.columns) for path in args.data]
    valid = [load_data(path, columns=args.columns) for path in args.validate or ()] or None
    fixed = tuple(f.strip() for f in args.fixed.split(",")) if args.fixed else ()

    def say(msg: str) -> None:
        if not args.quiet:
            print(msg, file=sys.stderr, flush=True)

    result = identify(
        data,
        validation=valid,
        init=args.init,
        fixed=fixed,
        multistart=args.multistart,
        seed=args.seed,
        max_nfev=args.max_nfev,
        name=args.name or Path(args.data[0]).stem,
        progress=say,
    )
    doc = result.to_dict()
    if not result.converged:
        if args.json:
            print(dump_json(doc))
        fp = result.fit_percent
        val = f", validation {fp['validation']:.2f} %" if fp["validation"] is not None else ""
        p = result.params
        print(
            f"identify: the fit did not converge: {result.reason}\n"
            f"identify: best fit found (not written): train {fp['train']:.2f} %{val}, "
            f"a1={p.a1:.6g} a2={p.a2:.6g} a3={p.a3:.6g} alpha={p.alpha:.6g} "
            f"beta={p.beta:.6g} gamma={p.gamma:.6g}, offset {result.offset:.6g} um",
            file=sys.stderr,
        )
        return EXIT_NO
    target.write_text(stage_toml(result, data))
    doc["out"] = str(out)
    if report is not None:
        from ..report.identification import write_identification_report

        doc["report"] = str(write_identification_report(result, report, stage_file=out))
    if args.json:
        print(dump_json(doc))
    else:
        fp = result.fit_percent
        val = f", validation {fp['validation']:.2f} %" if fp["validation"] is not None else ""
        print(f"{out}: fit {fp['train']:.2f} %{val}; residual RMS {result.residual_rms:.3g} um")
        if len(result.records) > 1:
            for rec in result.records:
                print(
                    f"  {rec['source']}: fit {rec['fit_percent']:.2f} %, sensor offset "
                    f"{rec['offset']:.6g} ± {Z95 * rec['offset_std_err']:.2g} um"
                )
        ext, dist = result.extensions, result.disturbance
        if ext:
            print(f"  model extensions chosen: {', '.join(ext['chosen']) or 'none'}")
        if dist is not None:
            cov = "-" if result.coverage is None else f"{100 * result.coverage:.1f} %"
            print(
                f"  disturbance bound: input_max {dist.input_max:.4g}, rate_max "
                f"{dist.rate_max:.4g}/s; held-out coverage {cov}"
            )
        for note in result.diagnostics:
            print(f"note: {note}")
    return EXIT_OK
