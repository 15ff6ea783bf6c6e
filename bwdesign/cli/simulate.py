"""``bwdesign simulate`` (registered in :mod:`bwdesign.cli`).

Runs the sampled-data tracking loop of :func:`bwdesign.sim.simulate` and
prints the steady-state metrics. Exit codes: 0 the loop ran and stayed
bounded, 1 it diverged (reported, not an error), 2 bad input with one
``error:`` line and nothing written.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from ..model.config import load_plant
from ..model.references import Sine, Step, Triangle
from ..output.files import FileTarget, prepare_file
from ..output.jsonenc import dump_json
from ..sim.closed_loop import simulate
from ..sim.result import SimulationResult
from .args import (
    EXIT_NO,
    EXIT_OK,
    UsageError,
    add_plant_args,
    finite_float,
    gains_triple,
    nonneg_float,
    positive_float,
)

__all__ = ["simulate_args", "run_simulate"]

MAX_SAMPLES = 20_000_000


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def simulate_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign simulate``."""
    add_plant_args(p)
    p.add_argument(
        "--reference",
        choices=("sine", "triangle", "step"),
        default="sine",
        help="reference kind (default sine)",
    )
    p.add_argument(
        "--amplitude",
        type=finite_float,
        required=True,
        metavar="A",
        help="reference amplitude (plant length unit; the step height for a step)",
    )
    p.add_argument("--offset", type=finite_float, default=0.0, metavar="O", help="reference offset")
    p.add_argument(
        "--frequency",
        type=positive_float,
        default=None,
        metavar="F",
        help="reference frequency (Hz; sine and triangle)",
    )
    p.add_argument(
        "--phase", type=finite_float, default=0.0, metavar="RAD", help="reference phase (rad)"
    )
    p.add_argument(
        "--rise-time",
        type=nonneg_float,
        default=0.0,
        metavar="S",
        help="step: quintic rise time (s); 0 = sharp step",
    )
    p.add_argument(
        "--t-step", type=nonneg_float, default=0.0, metavar="S", help="step: time of the step (s)"
    )
    p.add_argument(
        "--observer", choices=("phso", "eso", "ukf"), default="phso", help="observer (default phso)"
    )
    p.add_argument(
        "--gains",
        type=gains_triple,
        default=None,
        metavar="l1,l2,l3",
        help="continuous observer gains (1/s, 1/s^2, 1/s); required for phso and eso",
    )
    p.add_argument("--lambda1", type=positive_float, required=True, help="eq. (12) lambda1 (1/s)")
    p.add_argument("--lambda2", type=positive_float, required=True, help="eq. (12) lambda2 (1/s)")
    p.add_argument(
        "--form",
        choices=("continuous", "discrete"),
        default="continuous",
        help="eq. (12) as printed, or its sampled form (default continuous)",
    )
    p.add_argument(
        "--integral-rate",
        type=positive_float,
        default=None,
        metavar="RATE",
        help="integral action of the discrete form (1/s)",
    )
    p.add_argument("--dt", type=positive_float, required=True, help="sample time (s)")
    p.add_argument("--duration", type=positive_float, required=True, help="run length (s)")
    p.add_argument(
        "--noise-std",
        type=nonneg_float,
        default=0.0,
        metavar="S",
        help="measurement noise std (plant length unit)",
    )
    p.add_argument("--seed", type=_int, default=0, metavar="N", help="noise seed (default 0)")
    p.add_argument("--delay", action="store_true", help="one-sample computation delay")
    p.add_argument("--u-min", type=finite_float, default=None, metavar="V", help="input limit")
    p.add_argument("--u-max", type=finite_float, default=None, metavar="V", help="input limit")
    p.add_argument(
        "--true-plant",
        default=None,
        metavar="NAME_OR_TOML",
        help="simulate this plant instead of --plant (model mismatch)",
    )
    p.add_argument(
        "--csv",
        default=None,
        metavar="FILE",
        help="write the time series (t, x, xhat, u, x_d, e, z) to FILE: a new file, or one "
        "an earlier --csv wrote and nobody changed since (its first line says so)",
    )


def _reference(args: argparse.Namespace):
    if args.reference == "step":
        if args.frequency is not None:
            raise UsageError("--frequency does not apply to a step reference")
        return Step(
            amplitude=args.amplitude,
            offset=args.offset,
            t_step=args.t_step,
            rise_time=args.rise_time,
        )
    if args.frequency is None:
        raise UsageError(f"a {args.reference} reference needs --frequency (Hz)")
    if args.rise_time or args.t_step:
        raise UsageError("--rise-time and --t-step apply to a step reference only")
    cls = Sine if args.reference == "sine" else Triangle
    return cls(
        amplitude=args.amplitude, offset=args.offset, frequency=args.frequency, phase=args.phase
    )


def _write_csv(result: SimulationResult, target: FileTarget) -> None:
    cols = np.column_stack(
        [result.t, result.x, result.xhat, result.u, result.x_d, result.e, result.z]
    )
    header = "t,x1,x2,x3,x1hat,x2hat,x3hat,u,x_d,e,z"
    with target.open() as f:
        np.savetxt(f, cols, delimiter=",", header=header, comments="", fmt="%.10g")


def run_simulate(args: argparse.Namespace) -> int:
    """Run ``bwdesign simulate``; returns the exit code."""
    params = load_plant(args.plant)
    true_params = load_plant(args.true_plant) if args.true_plant else None
    reference = _reference(args)
    if args.observer in ("phso", "eso") and args.gains is None:
        raise UsageError(f"--observer {args.observer} needs --gains l1,l2,l3")
    n = args.duration / args.dt
    if n < 2:
        raise UsageError(f"--duration {args.duration:g} s holds fewer than 2 samples of --dt")
    if n > MAX_SAMPLES:
        raise UsageError(
            f"--duration/--dt = {n:.3g} samples exceeds the limit of {MAX_SAMPLES:.0e}"
        )
    if (args.u_min is None) != (args.u_max is None):
        raise UsageError("give both --u-min and --u-max, or neither")
    u_limits = None if args.u_min is None else (args.u_min, args.u_max)
    if args.integral_rate is not None and args.form != "discrete":
        raise UsageError("--integral-rate needs --form discrete")
    target = None
    if args.csv is not None:
        target = prepare_file(args.csv, command="simulate --csv", what="--csv")
    result = simulate(
        params,
        reference,
        dt=args.dt,
        duration=args.duration,
        observer=args.observer,
        gains=args.gains,
        lambda1=args.lambda1,
        lambda2=args.lambda2,
        form=args.form,
        integral_rate=args.integral_rate,
        u_limits=u_limits,
        true_params=true_params,
        noise_std=args.noise_std,
        seed=args.seed,
        delay=args.delay,
        allow_unbounded=args.allow_unbounded,
    )
    if target is not None:
        _write_csv(result, target)
    doc = result.to_dict()
    doc["plant"] = params.to_dict()
    doc["reference"] = reference.to_dict()
    doc["observer"] = args.observer
    doc["csv"] = str(target.path) if target else None
    if args.json:
        print(dump_json(doc))
    else:
        _print(result, params.length_unit, reference.describe(), args)
    return EXIT_OK if result.stable else EXIT_NO


def _print(result: SimulationResult, lu: str, ref_text: str, args: argparse.Namespace) -> None:
    s = result.settings
    print(
        f"plant: {s['plant'] or '(unnamed)'}" + (" (true plant differs)" if s["true_plant"] else "")
    )
    print(f"reference: {ref_text}")
    print(
        f"loop: {args.observer.upper()} observer, eq. (12) {s['controller']['form']} form, "
        f"lambda1 = {args.lambda1:g}, lambda2 = {args.lambda2:g} 1/s, dt = {args.dt:g} s"
        + (", one-sample delay" if args.delay else "")
    )
    if args.noise_std:
        print(f"noise: std {args.noise_std:g} {lu}, seed {args.seed}")
    if not result.stable:
        print(f"UNSTABLE: {result.status}")
        return
    m = result.metrics
    w0, w1 = result.window
    print(f"steady-state window: {w0:.6g} .. {w1:.6g} s ({m.samples} samples)")
    print(f"  MAXE = {m.maxe:.6g} {lu}")
    print(f"  ME   = {m.me:.6g} {lu}")
    print(f"  RMSE = {m.rmse:.6g} {lu}")
    e1, e2, e3 = result.estimation_rmse
    print(f"estimation RMSE: x1 {e1:.4g} {lu}, x2 {e2:.4g} {lu}/s, x3 {e3:.4g} {lu}")
    if not math.isclose(result.saturated_fraction, 0.0):
        print(f"input saturated {100 * result.saturated_fraction:.3g} % of the time")
