"""``bwdesign certify`` and ``bwdesign synthesize`` (registered in :mod:`bwdesign.cli`).

Exit codes: 0 certified (or gains found), 1 nothing certified (or infeasible, or
the robust observer certificate over a file's [uncertainty] does not hold), 2 bad
input with one ``error:`` line.

With ``--plant FILE.toml`` the file's ``[observer]`` gains, ``[sampling]`` dt,
``[envelope]`` and ``[synthesis]`` are the defaults of ``--gains``, ``--dt``,
``--udot-max``, ``--decay`` and ``--pole-radius`` (see :mod:`bwdesign.cli.stage`).
Rates are printed in the plant's input unit per second.
"""

from __future__ import annotations

import argparse
import math

from ..certify.results import CertificateReport, SynthesisResult
from ..certify.tiers import certify
from ..design.gains import synthesize
from ..model.config import load_config
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
from .stage import Stage, load_stage, resolved_copy

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
    p.add_argument(
        "--input-range",
        type=_input_range,
        default=None,
        metavar="LO,HI",
        help="with an [uncertainty] section in --plant FILE.toml: the inputs (input unit) "
        "the plant may be driven with, for the robust observer certificate; default: "
        "[controller] u_min, u_max when both are given, else the [reference]'s "
        "feedforward range",
    )
    p.add_argument(
        "--uncertainty-from",
        default=None,
        metavar="FILE.toml",
        help="take the [uncertainty] box from this stage file (e.g. the one bwdesign "
        "identify writes) instead of the --plant file's; relative half-widths apply to "
        "the --plant parameters",
    )
    p.add_argument(
        "--noise-max",
        type=nonneg_float,
        default=None,
        metavar="N",
        help="sensor noise bound |n| <= N (length unit) the robust certificate assumes "
        "(default 0). When the file has an [uncertainty] section the robust observer "
        "certificate over its box is also run, and the exit code is 1 if it does not hold",
    )


def _input_range(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        lo, hi = (float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LO,HI (two numbers), got {text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise argparse.ArgumentTypeError(f"expected finite LO < HI, got {text!r}")
    return lo, hi


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
        "(bwdesign.design.robust); needs [uncertainty], [reference] and a dt",
    )
    p.add_argument(
        "--noise-max",
        type=nonneg_float,
        default=None,
        metavar="N",
        help="with --robust: sensor noise bound |n| <= N (length unit) of the certified bounds "
        "(default 0)",
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


def _robust_request(args: argparse.Namespace, stage: Stage) -> dict:
    """``certify``'s robust keywords from the file's [uncertainty] (empty without one)."""
    cfg = stage.config
    box = None if cfg is None else cfg.uncertainty
    if args.uncertainty_from is not None:
        box = load_config(args.uncertainty_from).uncertainty
        if box is None:
            raise UsageError(f"--uncertainty-from {args.uncertainty_from}: no [uncertainty] box")
    if box is None:
        if args.input_range is not None or args.noise_max is not None:
            raise UsageError(
                "--input-range and --noise-max are for the robust observer certificate; "
                "it needs an [uncertainty] section (--plant FILE.toml or --uncertainty-from)"
            )
        return {}
    if args.dt is None:
        raise UsageError(
            "the robust observer certificate over [uncertainty] needs the sample time: "
            "give --dt or a [sampling] dt in the file"
        )
    ctrl = None if cfg is None else cfg.controller
    limits = None if ctrl is None else ctrl.input_limits()
    if limits is not None and not all(math.isfinite(v) for v in limits):
        limits = None  # a one-sided limit does not bound the input
    args.input_range = stage.default(args, "input_range", "[controller]", limits)
    if args.input_range is None and cfg is not None and cfg.reference is not None:
        from ..model.envelope import given_envelope
        from ..study.tracking import required_input

        env = cfg.envelope(allow_unbounded=args.allow_unbounded) or given_envelope(args.udot_max)
        rng = required_input(cfg, env, allow_unbounded=args.allow_unbounded)
        args.input_range = stage.default(args, "input_range", "[reference]", rng)
    if args.input_range is None:
        raise UsageError(
            "the robust observer certificate over [uncertainty] needs the input range: give "
            "--input-range LO,HI, or [controller] u_min and u_max, or a [reference]"
        )
    return {
        "uncertainty": box,
        "input_range": tuple(args.input_range),
        "noise_max": 0.0 if args.noise_max is None else args.noise_max,
    }


def _print_robust(rep: CertificateReport) -> None:
    rc = rep.robust
    p = rep.params
    lo, hi = rc.input_range
    print(
        f"robust observer over [uncertainty] ({rc.n_vertices} corners + {rc.n_interior} "
        f"interior points, u in [{lo:g}, {hi:g}] {p.input_unit}, |n| <= {rc.noise_max:g} "
        f"{p.length_unit}):"
    )
    if rc.holds:
        print(
            f"  holds: yes: steady |x1hat - x1| <= {rc.estimation_bound:.4g} {p.length_unit}, "
            f"|x3hat - x3| <= {rc.x3_estimation_bound:.4g} {p.length_unit}, "
            f"convergence >= {rc.decay:.4g} 1/s"
        )
    else:
        print(f"  holds: no: {rc.status}")


def run_certify(args: argparse.Namespace) -> int:
    """Run ``bwdesign certify``; exit 0 when a tier holds (and the robust certificate, when
    the file has an [uncertainty] section), 1 otherwise."""
    args = resolved_copy(args)
    stage = load_stage(args.plant)
    params = stage.params
    if stage.config is not None:
        args.gains = stage.default(args, "gains", "[observer]", stage.config.gains)
    if args.gains is None:
        raise UsageError(
            "--gains l1,l2,l3 is required, unless --plant is a stage file with [observer] gains"
        )
    _envelope(args, stage)
    robust = _robust_request(args, stage)
    rep = certify(
        params,
        args.gains,
        udot_max=args.udot_max,
        decay=args.decay,
        dt=args.dt,
        allow_unbounded=args.allow_unbounded,
        **robust,
    )
    if args.json:
        print(dump_json(_json(rep.to_dict(), params, stage)))
    else:
        _note(stage)
        _print_report(rep)
        if rep.robust is not None:
            _print_robust(rep)
    ok = rep.certified and (rep.robust is None or rep.robust.holds)
    return EXIT_OK if ok else EXIT_NO


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
        + (
            f"poles within {res.pole_radius:g} rad/s"
            if math.isfinite(res.pole_radius)
            else "no pole region"
        )
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
    args = resolved_copy(args)
    if args.robust:
        given = [
            f"--{k.replace('_', '-')}"
            for k in ("decay", "pole_radius")
            if getattr(args, k) is not None
        ]
        if given:
            raise UsageError(
                f"{' and '.join(given)} {'does' if len(given) == 1 else 'do'} not apply to "
                "--robust (it designs the sampled loop for the smallest certified tracking bound)"
            )
    else:
        for opt in ("observer", "noise_max"):
            if getattr(args, opt) is not None:
                raise UsageError(f"--{opt.replace('_', '-')} applies to --robust only")
    stage = load_stage(args.plant)
    params = stage.params
    _envelope(args, stage)
    if stage.config is not None:
        spec = stage.config.synthesis or {}
        args.pole_radius = stage.default(
            args, "pole_radius", "[synthesis]", spec.get("pole_radius")
        )
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
