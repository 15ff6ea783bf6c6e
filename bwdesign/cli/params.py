"""``bwdesign params``."""

from __future__ import annotations

import argparse

from ..model.config import FORMS, load_plant
from ..model.structural import StructuralParams
from ..model.summary import plant_summary
from ..output.jsonenc import dump_json
from .args import EXIT_OK

__all__ = ["run_params"]


def run_params(args: argparse.Namespace) -> int:
    """Run ``bwdesign params`` (registered in :mod:`bwdesign.cli.main`)."""
    params = load_plant(args.plant, forms=FORMS)
    if isinstance(params, StructuralParams):
        return _structural(params, args.json)
    doc = plant_summary(params)
    if args.json:
        print(dump_json(doc))
        return EXIT_OK
    lu, iu = params.length_unit, params.input_unit
    print(f"plant: {params.name or '(unnamed)'}")
    if "note" in doc:
        print(f"  {doc['note']}")
    units = {
        "a1": "1/s^2",
        "a2": "1/s",
        "a3": f"{lu}/({iu} s^2)",
        "alpha": f"{lu}/{iu}",
        "beta": f"1/{iu}",
        "gamma": f"1/{iu}",
    }
    for k, unit in units.items():
        print(f"  {k:<6} = {getattr(params, k):<14.8g} {unit}")
    if params.physical is not None:
        ph = params.physical
        print("physical quantities:")
        for k in ("m", "b", "k", "d", "alpha0"):
            print(f"  {k:<6} = {getattr(ph, k):.8g}")
    d = doc["derived"]
    print("linear part:")
    print(f"  natural frequency sqrt(a1)/(2 pi) = {d['natural_frequency_hz']:.6g} Hz")
    print(f"  damping ratio a2/(2 sqrt(a1))     = {d['damping_ratio']:.4g}")
    print(f"  static gain a3/a1                 = {d['static_gain']:.6g} {lu}/{iu}")
    v = doc["bounded_class"]
    print(f"bounded class: {'yes' if v['bounded'] else 'NO'}")
    print(f"  {v['reason']}")
    return EXIT_OK


def _structural(params: StructuralParams, as_json: bool) -> int:
    """``bwdesign params`` for a structural stage: parameters with units and the verdict."""
    verdict = params.bounded_class()
    if as_json:
        print(dump_json({"plant": params.to_dict(), "bounded_class": verdict.to_dict()}))
        return EXIT_OK
    print(f"plant: {params.name or '(unnamed)'} (structural Bouc-Wen form)")
    for k, unit in params.units.items():
        print(f"  {k:<6} = {getattr(params, k):<14.8g} {unit}")
    print(f"bounded for every input: {'yes' if verdict.bounded else 'no'}")
    print(f"  {verdict.reason}")
    return EXIT_OK
