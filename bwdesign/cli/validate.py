"""``bwdesign validate``: a stage file (either form) simulated on a record's input and scored.

Prints the fit percent and the RMS error in the record's output unit (the stage's
length unit). Exit codes: 0 scored; 2 bad input (one ``error:`` line).
"""

from __future__ import annotations

import argparse

from ..identify.data import load_data
from ..identify.score import score_record
from ..model.config import FORMS, load_plant
from ..output.jsonenc import dump_json
from .args import EXIT_OK, add_plant_args

__all__ = ["validate_args", "run_validate"]


def validate_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign validate``."""
    add_plant_args(p)
    p.add_argument("--data", required=True, metavar="RECORD.csv", help="record (.csv/.npz)")
    p.add_argument(
        "--columns", metavar="T,U,Y", help="names of the time, input, output columns (t,u,y)"
    )
    p.add_argument(
        "--periodic",
        action="store_true",
        help="the record is one period of a periodic input: simulate to the periodic steady "
        "state and score that period",
    )


def run_validate(args: argparse.Namespace) -> int:
    """Run ``bwdesign validate``."""
    plant = load_plant(args.plant, forms=FORMS)
    data = load_data(args.data, columns=args.columns)
    score = score_record(plant, data, periodic=args.periodic, allow_unbounded=args.allow_unbounded)
    unit = plant.length_unit
    doc = {
        "plant": args.plant,
        "form": getattr(plant, "form", "piezo"),
        "data": args.data,
        "samples": data.n,
        "periodic": bool(args.periodic),
        "unit": unit,
        **score.to_dict(),
    }
    if args.json:
        print(dump_json(doc))
        return EXIT_OK
    err = score.integration_error
    extra = "" if err is None else f" (integration error estimate {err:.2g} {unit})"
    print(
        f"{args.data}: fit {score.fit_percent:.4f} %, RMS error {score.rms_error:.4g} {unit}{extra}"
    )
    return EXIT_OK
