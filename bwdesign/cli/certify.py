"""``bwdesign certify`` and ``bwdesign synthesize`` (registered in :mod:`bwdesign.cli`).

Exit codes: 0 certified (or gains found), 1 nothing certified (or infeasible),
2 bad input with one ``error:`` line.
"""

from __future__ import annotations

import argparse
import math

from ..certify.results import CertificateReport, SynthesisResult
from ..certify.synthesis import synthesize
from ..certify.tiers import certify
from ..model.config import load_plant
from ..output.jsonenc import dump_json
from .args import EXIT_NO, EXIT_OK, add_plant_args, gains_triple, nonneg_float, positive_float

__all__ = ["certify_args", "run_certify", "synthesize_args", "run_synthesize"]


def _envelope_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--udot-max",
        required=True,
        type=positive_float,
        metavar="V",
        help="bound on the input rate |u'| (V/s)",
    )
    p.add_argument(
        "--decay",
        type=nonneg_float,
        default=0.0,
        metavar="MU",
        help="required decay rate of the estimation error (1/s, default 0)",
    )
    p.add_argument(
        "--dt",
        type=positive_float,
        default=None,
        metavar="TS",
        help="sample time (s): adds the sampled tier / synthesises the sampled observer",
    )


def certify_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign certify``."""
    add_plant_args(p)
    p.add_argument(
        "--gains",
        required=True,
        type=gains_triple,
        metavar="l1,l2,l3",
        help="continuous observer gains (1/s, 1/s^2, 1/s), e.g. 8,64,-512",
    )
    _envelope_args(p)


def synthesize_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign synthesize``."""
    add_plant_args(p)
    _envelope_args(p)
    p.add_argument(
        "--pole-radius",
        type=positive_float,
        default=None,
        metavar="R",
        help="observer poles within |s| < R (rad/s); default 10 sqrt(a1), at most 1/dt",
    )


def _num(x: float | None, fmt: str = ".4g") -> str:
    if x is None:
        return "-"
    if math.isinf(x):
        return "inf"
    return format(x, fmt)


def _print_report(rep: CertificateReport) -> None:
    p = rep.params
    head = f"plant: {p.name or '(unnamed)'}"
    if rep.gains is not None:
        head += f"   gains l = ({', '.join(f'{g:g}' for g in rep.gains)})"
    print(head)
    line = f"envelope: |u'| <= {rep.udot_max:g} V/s, decay >= {rep.decay:g} 1/s"
    if rep.dt is not None:
        K = ", ".join(f"{k:.6g}" for k in rep.discrete_gains or ())
        line += f", dt = {rep.dt:g} s (discrete gain K = ({K}))"
    print(line)
    print(f"{'tier':<10} {'holds':<6} {'max |u_dot| (V/s)':>18} {'decay rate (1/s)':>17}  status")
    for c in rep.certificates:
        env = _num(c.max_udot) + ("+" if c.max_udot_capped else "")
        print(
            f"{c.name:<10} {'yes' if c.holds else 'no':<6} {env:>18} "
            f"{_num(c.decay_rate):>17}  {c.status}"
        )
    if any(c.max_udot_capped for c in rep.certificates):
        print("  (+: still certified at the search limit; the tier may hold for every rate)")
    if rep.certified:
        print(f"certified: yes (best tier: {rep.best})")
    else:
        print("certified: no (no tier holds)")


def run_certify(args: argparse.Namespace) -> int:
    """Run ``bwdesign certify``; exit 0 when a tier holds, 1 when none does."""
    params = load_plant(args.plant)
    rep = certify(
        params,
        args.gains,
        udot_max=args.udot_max,
        decay=args.decay,
        dt=args.dt,
        allow_unbounded=args.allow_unbounded,
    )
    if args.json:
        print(dump_json(rep.to_dict()))
    else:
        _print_report(rep)
    return EXIT_OK if rep.certified else EXIT_NO


def _print_synthesis(res: SynthesisResult) -> None:
    print(f"plant: {res.params.name or '(unnamed)'}   tier: {res.tier}")
    line = (
        f"request: |u'| <= {res.udot_max:g} V/s, decay >= {res.decay:g} 1/s, "
        f"poles within {res.pole_radius:g} rad/s"
    )
    if res.dt is not None:
        line += f", dt = {res.dt:g} s"
    print(line)
    if res.feasible:
        if res.gains is not None:
            print(f"gains l = {', '.join(f'{g:.8g}' for g in res.gains)}")
        if res.discrete_gains is not None:
            print(f"discrete gain K = {', '.join(f'{k:.8g}' for k in res.discrete_gains)}")
        print(f"feasible: yes: {res.reason}")
        if res.report is not None:
            print()
            _print_report(res.report)
    else:
        print(f"feasible: no ({res.binding}): {res.reason}")


def run_synthesize(args: argparse.Namespace) -> int:
    """Run ``bwdesign synthesize``; exit 0 with gains, 1 when infeasible."""
    params = load_plant(args.plant)
    res = synthesize(
        params,
        udot_max=args.udot_max,
        decay=args.decay,
        pole_radius=args.pole_radius,
        dt=args.dt,
        allow_unbounded=args.allow_unbounded,
    )
    if args.json:
        print(dump_json(res.to_dict()))
    else:
        _print_synthesis(res)
    return EXIT_OK if res.feasible else EXIT_NO
