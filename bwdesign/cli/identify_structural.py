"""``bwdesign identify --form structural``: the structural Bouc-Wen form from (t, u, y) records.

Exit codes as for the piezo form (:mod:`bwdesign.cli.identify`): 0 fitted; 1 the fit
did not converge (nothing written); 2 bad input (one ``error:`` line, nothing written).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..identify.data import load_data
from ..identify.structural import DETERMINED, identify_structural, structural_stage_toml
from ..output.files import prepare_directory, prepare_file
from ..output.jsonenc import dump_json
from .args import EXIT_NO, EXIT_OK, UsageError

__all__ = ["run_identify_structural"]


def _units(text: str) -> tuple[str, str]:
    parts = tuple(p.strip() for p in text.split(","))
    if len(parts) != 2 or not all(parts):
        raise UsageError(f"--units must name the length and the input unit, e.g. m,N; got {text!r}")
    return parts  # type: ignore[return-value]


def run_identify_structural(args: argparse.Namespace) -> int:
    """Run ``bwdesign identify --form structural`` (options of :mod:`bwdesign.cli.identify`)."""
    for opt in ("init", "fixed"):
        if getattr(args, opt):
            raise UsageError(
                f"--{opt} applies to the piezo form; the structural fit needs no initial guess"
            )
    out = Path(args.out)
    if out.suffix.lower() != ".toml":
        raise UsageError(f"--out must be a .toml file, got {args.out!r}")
    if args.max_nfev < 1:
        raise UsageError("--max-nfev must be >= 1")
    units = _units(args.units)
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

    def say(msg: str) -> None:
        if not args.quiet:
            print(msg, file=sys.stderr, flush=True)

    fit = identify_structural(
        data,
        periodic=args.periodic,
        validation=valid,
        name=args.name or Path(args.data[0]).stem,
        units=units,
        max_nfev=args.max_nfev,
        progress=say,
    )
    doc = fit.to_dict()
    if not fit.converged:
        if args.json:
            print(dump_json(doc))
        print(
            f"identify: the fit did not converge: {fit.reason}; nothing written "
            f"(best residual RMS {fit.residual_rms:.4g} {units[0]})",
            file=sys.stderr,
        )
        return EXIT_NO
    target.write_text(structural_stage_toml(fit, data))
    doc["out"] = str(out)
    if report is not None:
        from ..report.structural_identification import write_structural_report

        doc["report"] = str(write_structural_report(fit, report, stage_file=out))
    if args.json:
        print(dump_json(doc))
        return EXIT_OK
    fp = fit.fit_percent
    val = (
        ""
        if fit.residual_rms_validation is None
        else (f"; validation RMS error {fit.residual_rms_validation:.4g} {units[0]}")
    )
    print(
        f"{out}: fit {fp['train']:.4f} %, residual RMS {fit.residual_rms:.4g} {units[0]}{val} "
        f"({fit.seconds:.1f} s)"
    )
    for n in DETERMINED:
        lo, hi = fit.ci95[n]
        print(f"  {n:<10} = {fit.values[n]:.8g}  95 % [{lo:.8g}, {hi:.8g}]")
    print("  beta, gamma, delta apart: not determined (beta = 1 in the stage file is a convention)")
    return EXIT_OK
