"""``bwdesign certify`` and ``bwdesign synthesize`` (registered in :mod:`bwdesign.cli`).

Exit codes: 0 certified (or gains found), 1 nothing certified (or infeasible),
2 bad input with one ``error:`` line.

With ``--plant FILE.toml`` the file's ``[observer]`` gains, ``[sampling]`` dt,
``[envelope]`` and ``[synthesis]`` are the defaults of ``--gains``, ``--dt``,
``--udot-max``, ``--decay`` and ``--pole-radius`` (see :mod:`bwdesign.cli.stage`).
Rates are printed in the plant's input unit per second.
"""

from __future__ import annotations

import argparse
import math

from ..certify.results import CertificateReport, SynthesisResult
from ..certify.synthesis import synthesize
from ..certify.tiers import certify
from ..output.jsonenc import dump_json
from .args import (
    EXIT_NO,
    EXIT_OK,
    UsageError,
    add_plant_args,
    gains_triple,
    nonneg_float,
    positive_float,
)
from .stage import Stage, load_stage

__all__ = ["certify_args", "run_certify", "synthesize_args", "run_synthesize"]


def _envelope_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--udot-max",
        type=positive_float,
        default=None,
        metavar="V",
        help="bound on the input rate |u'| (input unit/s, V/s by default); "
        "default: the [envelope] of a --plant FILE.toml",
    )
    p.add_argument(
        "--decay",
        type=nonneg_float,
        default=None,
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
        type=gains_triple,
        default=None,
        metavar="l1,l2,l3",
        help="continuous observer gains (1/s, 1/s^2, 1/s), e.g. 8,64,-512; "
        "default: [observer] gains of a --plant FILE.toml",
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
    p.add_argument(
        "--tier",
        choices=("theorem1", "lipschitz", "sector", "sampled"),
        default=None,
        help="the tier to synthesise for (default: sampled with a dt, else sector); theorem1 "
        "and lipschitz are continuous and report the envelope their gains reach",
    )
    p.add_argument(
        "--robust",
        action="store_true",
        help="design the sampled tracking loop (observer gains, lambda, integral rate) against "
        "the stage file's [uncertainty] box and certify it over every corner "
        "(bwdesign.sim.robust_design); needs [uncertainty], [reference] and a dt",
    )
    p.add_argument(
        "--noise-max",
        type=nonneg_float,
        default=0.0,
        metavar="N",
        help="with --robust: sensor noise bound |n| <= N (length unit) of the certified bounds",
    )
    p.add_argument(
        "--observer",
        choices=("phso", "phdo"),
        default=None,
        help="with --robust: the loop's observer (default phdo, the disturbance observer with "
        "the tuning's (l1, l2, 0, l3), certified on its lumped error; phso: the paper's)",
    )


def _num(x: float | None, fmt: str = ".4g") -> str:
    if x is None:
        return "-"
    if math.isinf(x):
        return "inf"
    return format(x, fmt)


def _envelope(args: argparse.Namespace, stage: Stage) -> None:
    """Fill ``--udot-max``, ``--dt`` and ``--decay`` from the stage file where not given."""
    cfg = stage.config
    if cfg is not None:
        env = cfg.envelope(allow_unbounded=args.allow_unbounded) if args.udot_max is None else None
        args.udot_max = stage.default(
            args, "udot_max", "[envelope]", None if env is None else env.udot_max
        )
        args.dt = stage.default(args, "dt", "[sampling]", cfg.dt)
        args.decay = stage.default(args, "decay", "[synthesis]", (cfg.synthesis or {}).get("decay"))
    if args.udot_max is None:
        raise UsageError(
            "--udot-max is required (input-rate bound, input unit/s), unless --plant is a "
            "stage file with an [envelope] section"
        )
    if args.decay is None:
        args.decay = 0.0


def _capped_notes(rep: CertificateReport, ru: str) -> list[str]:
    """One sentence per tier whose rate search stopped at its limit, read off the data."""
    notes = []
    for c in rep.certificates:
        if not c.max_udot_capped:
            continue
        if c.holds:
            notes.append(
                f"  {c.name}: still certified at the search limit {_num(c.max_udot)} {ru} "
                "(marked +): the tier may hold for every rate"
            )
        else:
            notes.append(
                f"  {c.name}: the rate search stopped at its limit {_num(c.max_udot)} {ru} "
                f"(marked +) while still certified there, but the tier does not hold at the "
                f"requested |u'| <= {rep.udot_max:g} {ru}"
            )
    return notes


def _print_report(rep: CertificateReport) -> None:
    p = rep.params
    ru = f"{p.input_unit}/s"
    head = f"plant: {p.name or '(unnamed)'}"
    if rep.gains is not None:
        head += f"   gains l = ({', '.join(f'{g:g}' for g in rep.gains)})"
    print(head)
    line = f"envelope: |u'| <= {rep.udot_max:g} {ru}, decay >= {rep.decay:g} 1/s"
    if rep.dt is not None:
        K = ", ".join(f"{k:.6g}" for k in rep.discrete_gains or ())
        line += f", dt = {rep.dt:g} s (discrete gain K = ({K}))"
    print(line)
    rate_head = f"max |u_dot| ({ru})"
    print(f"{'tier':<10} {'holds':<6} {rate_head:>18} {'decay rate (1/s)':>17}  status")
    for c in rep.certificates:
        env = _num(c.max_udot) + ("+" if c.max_udot_capped else "")
        print(
            f"{c.name:<10} {'yes' if c.holds else 'no':<6} {env:>18} "
            f"{_num(c.decay_rate):>17}  {c.status}"
        )
    for note in _capped_notes(rep, ru):
        print(note)
    if rep.certified:
        print(f"certified: yes (best tier: {rep.best})")
    else:
        print("certified: no (no tier holds)")


def run_certify(args: argparse.Namespace) -> int:
    """Run ``bwdesign certify``; exit 0 when a tier holds, 1 when none does."""
    stage = load_stage(args.plant)
    params = stage.params
    if stage.config is not None:
        args.gains = stage.default(args, "gains", "[observer]", stage.config.gains)
    if args.gains is None:
        raise UsageError(
            "--gains l1,l2,l3 is required, unless --plant is a stage file with [observer] gains"
        )
    _envelope(args, stage)
    rep = certify(
        params,
        args.gains,
        udot_max=args.udot_max,
        decay=args.decay,
        dt=args.dt,
        allow_unbounded=args.allow_unbounded,
    )
    if args.json:
        print(dump_json(_json(rep.to_dict(), params, stage)))
    else:
        _note(stage)
        _print_report(rep)
    return EXIT_OK if rep.certified else EXIT_NO


def _json(doc: dict, params, stage: Stage) -> dict:
    doc["units"] = {
        "udot_max": f"{params.input_unit}/s",
        "max_udot": f"{params.input_unit}/s",
        "decay": "1/s",
        "gains": ["1/s", "1/s^2", "1/s"],
        "length": params.length_unit,
        "input": params.input_unit,
    }
    doc["defaults_from_file"] = stage.to_dict()
    return doc


def _note(stage: Stage) -> None:
    note = stage.note()
    if note is not None:
        print(note)


def _print_synthesis(res: SynthesisResult) -> None:
    print(f"plant: {res.params.name or '(unnamed)'}   tier: {res.tier}")
    line = (
        f"request: |u'| <= {res.udot_max:g} {res.params.input_unit}/s, "
        f"decay >= {res.decay:g} 1/s, "
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
    stage = load_stage(args.plant)
    params = stage.params
    _envelope(args, stage)
    if stage.config is not None:
        spec = stage.config.synthesis or {}
        args.pole_radius = stage.default(
            args, "pole_radius", "[synthesis]", spec.get("pole_radius")
        )
    if args.observer is not None and not args.robust:
        raise UsageError("--observer applies to --robust only")
    if args.robust:
        if args.tier is not None:
            raise UsageError(
                "--tier and --robust do not go together (--robust is the sampled loop)"
            )
        from .robust_synth import run_robust

        return run_robust(args, stage)
    res = synthesize(
        params,
        udot_max=args.udot_max,
        decay=args.decay,
        pole_radius=args.pole_radius,
        dt=args.dt,
        allow_unbounded=args.allow_unbounded,
        tier=args.tier,
    )
    if args.json:
        print(dump_json(_json(res.to_dict(), params, stage)))
    else:
        _note(stage)
        _print_synthesis(res)
    return EXIT_OK if res.feasible else EXIT_NO
