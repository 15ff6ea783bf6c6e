"""``bwdesign simulate`` (registered in :mod:`bwdesign.cli`).

Runs the sampled-data tracking loop of :func:`bwdesign.sim.simulate` and
prints the steady-state metrics. Exit codes: 0 the loop ran and stayed
bounded, 1 it diverged (reported, not an error), 2 bad input with one
``error:`` line and nothing written.

With ``--plant FILE.toml`` the file's ``[observer]`` gains (PHSO and ESO),
``[controller]`` lambda1, lambda2, u_min, u_max, ``[sampling]`` dt,
``[reference]`` (when no reference option is given) and ``[envelope]`` (the
UKF's ``--udot-max``) are the defaults of the options not given; what was
taken from the file is printed. An option that does not apply to the run is
an error.

``--controller pi|pid|pi-bwff|pi-piff`` runs a baseline instead of eq. (12) with an
observer (:mod:`bwdesign.control.baselines`: PI or PID on the measurement, with the
inverse Bouc–Wen or the Prandtl–Ishlinskii feedforward), tuned by the phase-margin
rule of :func:`bwdesign.control.baseline_tuning.tune_baseline` (``--phase-margin``)
or with ``--kp --ki [--kd --tf]``; the observer and eq. (12) options are then
errors. The baseline's nominal linear loop is analysed first: when it is not stable
the margins are printed and the exit code is 1 (the run is still reported).
``--mismatch a1=+2%,alpha=-10%`` simulates the ``--plant`` model with those signed
parameter changes (relative with ``%``, else absolute): an ``[uncertainty]`` corner.

``--tuning digital`` runs the loop with :func:`bwdesign.design.digital_tuning`
chosen for the stage, ``--dt`` and ``--delay`` (observer gains for the chosen
``--observer``, eq. (12) discrete form, lambdas, integral action); then
``--gains``, ``--lambda1``, ``--lambda2``, ``--form`` and ``--integral-rate`` are
errors, and the JSON's ``tuning`` says what was used.
"""

from __future__ import annotations

import argparse
import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..control.baseline_tuning import BaselineAnalysis, analyze_baseline, make_baseline
from ..control.baselines import BASELINE_KINDS
from ..control.controllers import TuningWarning, make_controller
from ..control.loop import ON_REFERENCE, ClosedLoop, Start
from ..design.tuning import digital_tuning
from ..model.config import load_plant
from ..model.mismatch import apply_mismatch
from ..model.params import MODEL_FIELDS, BoucWenParams
from ..model.references import Reference, Sine, Step, Triangle
from ..observers.spec import N_GAINS, OBSERVER_KINDS, ObserverSpec
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
    integer,
    nonneg_float,
    observer_gains_arg,
    positive_float,
)
from .stage import Stage, load_stage, resolved_copy

__all__ = ["simulate_args", "run_simulate", "simulate_request", "SimulateRequest"]

MAX_SAMPLES = 20_000_000


def simulate_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign simulate``."""
    add_plant_args(p)
    _reference_args(p)
    _loop_args(p)
    _baseline_args(p)
    _run_args(p)


#: ``--controller`` choices: eq. (12) with an observer, or a baseline.
CONTROLLERS = ("eq12", *BASELINE_KINDS)
_BASELINE_OPTIONS = ("kp", "ki", "kd", "tf", "phase_margin")
_OBSERVER_OPTIONS = (
    "observer", "gains", "tuning", "udot_max", "lambda1", "lambda2", "integral_rate",
)  # fmt: skip


def _baseline_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--controller",
        choices=CONTROLLERS,
        default="eq12",
        help="eq12 (default): eq. (12) with --observer; pi, pid: a PI or PID on the measured "
        "output; pi-bwff: PI with the exact inverse Bouc-Wen feedforward; pi-piff: PI with a "
        "Prandtl-Ishlinskii compensator fitted to the model's quasi-static loops",
    )
    p.add_argument("--kp", type=finite_float, default=None, help="baseline: proportional gain")
    p.add_argument("--ki", type=finite_float, default=None, help="baseline: integral gain (1/s)")
    p.add_argument("--kd", type=finite_float, default=None, help="pid: derivative gain (s)")
    p.add_argument(
        "--tf", type=finite_float, default=None, help="pid: derivative filter time constant (s)"
    )
    p.add_argument(
        "--phase-margin",
        type=positive_float,
        default=None,
        metavar="DEG",
        help="baseline: the tuning rule's phase margin (deg, default 60; no --kp/--ki)",
    )
    p.add_argument(
        "--mismatch",
        default=None,
        metavar="NAME=CHANGE,...",
        help="simulate the --plant model with these parameter changes (a1=+2%%: relative, "
        "alpha=-0.01: absolute), e.g. an [uncertainty] corner; not with --true-plant",
    )


def _reference_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--reference",
        choices=("sine", "triangle", "step"),
        default=None,
        help="reference kind (default sine, or the [reference] of a --plant FILE.toml)",
    )
    p.add_argument(
        "--amplitude",
        type=finite_float,
        default=None,
        metavar="A",
        help="reference amplitude (plant length unit; the step height for a step); "
        "required unless the reference comes from a --plant FILE.toml",
    )
    p.add_argument(
        "--offset",
        type=finite_float,
        default=None,
        metavar="O",
        help="reference offset (plant length unit, default 0)",
    )
    p.add_argument(
        "--frequency",
        type=positive_float,
        default=None,
        metavar="F",
        help="reference frequency (Hz; sine and triangle)",
    )
    p.add_argument(
        "--phase", type=finite_float, default=None, metavar="RAD", help="reference phase (rad)"
    )
    p.add_argument(
        "--rise-time",
        type=nonneg_float,
        default=None,
        metavar="S",
        help="step: quintic rise time (s); 0 = sharp step",
    )
    p.add_argument(
        "--t-step", type=nonneg_float, default=None, metavar="S", help="step: time of the step (s)"
    )


def _loop_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--observer",
        choices=OBSERVER_KINDS,
        default=None,
        help="observer (default phso; phdo: the hysteresis observer with a disturbance state)",
    )
    p.add_argument(
        "--gains",
        type=observer_gains_arg,
        default=None,
        metavar="l1,l2,l3[,l4]",
        help="continuous observer gains (1/s, 1/s^2, 1/s[, 1/s]): three for phso and eso, four "
        "for phdo; required unless --tuning digital (an error for ukf, which has none)",
    )
    p.add_argument(
        "--tuning",
        choices=("digital",),
        default=None,
        help="digital: gains, lambdas and integral action from bwdesign.design.digital_tuning "
        "for this stage, --dt, --delay and --observer (no --gains, --lambda1, --lambda2)",
    )
    p.add_argument(
        "--udot-max",
        type=positive_float,
        default=None,
        metavar="V",
        help="ukf: input-rate envelope for its process noise (input unit/s); default derived "
        "from a periodic reference (margin 1.1) or the [envelope] of a --plant FILE.toml",
    )
    p.add_argument("--lambda1", type=positive_float, default=None, help="eq. (12) lambda1 (1/s)")
    p.add_argument("--lambda2", type=positive_float, default=None, help="eq. (12) lambda2 (1/s)")
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
    p.add_argument("--dt", type=positive_float, default=None, help="sample time (s)")


def _run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=positive_float, required=True, help="run length (s)")
    p.add_argument(
        "--noise-std",
        type=nonneg_float,
        default=0.0,
        metavar="S",
        help="measurement noise std (plant length unit)",
    )
    p.add_argument("--seed", type=integer, default=0, metavar="N", help="noise seed (default 0)")
    p.add_argument("--delay", action="store_true", help="one-sample computation delay")
    p.add_argument(
        "--start-on-reference",
        action="store_true",
        help="start plant and estimate at (x_d(0), x_d'(0), 0) with the feedforward input "
        "held before t = 0 (as the report's runs do; default: from rest, u = 0)",
    )
    p.add_argument(
        "--u-min", type=finite_float, default=None, metavar="V", help="input limit (input unit)"
    )
    p.add_argument(
        "--u-max", type=finite_float, default=None, metavar="V", help="input limit (input unit)"
    )
    p.add_argument(
        "--true-plant",
        default=None,
        metavar="NAME_OR_TOML",
        help="simulate this plant instead of --plant (model mismatch); of a stage file "
        "only [plant] is used",
    )
    p.add_argument(
        "--csv",
        default=None,
        metavar="FILE",
        help="write the time series (t, x, xhat, u, x_d, e, z) to FILE: a new file, or one "
        "an earlier --csv wrote and nobody changed since (its first line says so)",
    )


_REFERENCE_OPTIONS = (
    "reference",
    "amplitude",
    "offset",
    "frequency",
    "phase",
    "rise_time",
    "t_step",
)


def _reference(args: argparse.Namespace, stage: Stage) -> Reference:
    given = [o for o in _REFERENCE_OPTIONS if getattr(args, o) is not None]
    if not given and stage.config is not None and stage.config.reference is not None:
        stage.used["--reference"] = "[reference]"
        return stage.config.reference
    if args.amplitude is None:
        raise UsageError(
            "--amplitude is required (or a --plant FILE.toml with a [reference] section and "
            "no reference option)"
        )
    args.reference = args.reference or "sine"
    args.offset = 0.0 if args.offset is None else args.offset
    if args.reference == "step":
        if args.phase is not None:
            raise UsageError("--phase does not apply to a step reference")
        args.rise_time = args.rise_time or 0.0
        args.t_step = args.t_step or 0.0
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
    if args.rise_time is not None or args.t_step is not None:
        raise UsageError("--rise-time and --t-step apply to a step reference only")
    args.phase = 0.0 if args.phase is None else args.phase
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


@dataclass(frozen=True)
class SimulateRequest:
    """What ``bwdesign simulate`` runs: resolved once from the command line and the file.

    The argparse namespace is read, never changed: the options a ``--plant FILE.toml``
    fills in are resolved on a copy.
    """

    stage: Stage
    loop: ClosedLoop
    reference: Reference
    duration: float
    true_params: BoucWenParams | None
    noise_std: float
    seed: int
    csv: str | None
    json: bool
    tuning: dict | None
    options: dict  # the resolved options, for the printed summary
    analysis: BaselineAnalysis | None = None  # a baseline's nominal linear loop


def simulate_request(namespace: argparse.Namespace) -> SimulateRequest:
    """Validate the options of ``bwdesign simulate`` and resolve the file's defaults.

    Raises
    ------
    UsageError, InputError, ConfigError
        One ``error:`` line on the command line.
    """
    args = resolved_copy(namespace)  # resolved here; the caller's is untouched
    stage = load_stage(args.plant)
    params = stage.params
    if args.true_plant and args.mismatch:
        raise UsageError("give --true-plant or --mismatch, not both")
    true_params = load_plant(args.true_plant) if args.true_plant else None
    if args.mismatch:
        true_params = apply_mismatch(args.mismatch, params, name="--mismatch")
    if args.controller != "eq12":
        return _baseline_request(args, stage, true_params)
    given = [f"--{o.replace('_', '-')}" for o in _BASELINE_OPTIONS if getattr(args, o) is not None]
    if given:
        raise UsageError(f"{', '.join(given)} apply to a baseline --controller only")
    args.observer = args.observer or "phso"
    if args.tuning is not None:
        given = [
            f"--{o.replace('_', '-')}"
            for o in ("gains", "lambda1", "lambda2", "integral_rate")
            if getattr(args, o) is not None
        ] + (["--form"] if args.form != "continuous" else [])
        if given:
            raise UsageError(
                f"--tuning {args.tuning} chooses the gains and constants; drop {', '.join(given)}"
            )
        if args.observer == "ukf":
            raise UsageError(
                "--tuning digital applies to phso, eso and phdo (the UKF has no gains)"
            )
    _file_defaults(args, stage)
    reference = _reference(args, stage)
    if args.observer == "ukf" and args.gains is not None:
        raise UsageError(
            "--gains does not apply to --observer ukf (the UKF has no gains; its noise model "
            "is set by --udot-max and --noise-std)"
        )
    if args.observer != "ukf" and args.udot_max is not None:
        raise UsageError("--udot-max applies to --observer ukf only (the UKF's process noise)")
    if args.tuning is not None and args.dt is None:
        raise UsageError("--dt is required (or a --plant FILE.toml that sets it)")
    tuning = _tuning(args, params, stage) if args.tuning is not None else None
    if args.observer in N_GAINS and args.gains is None:
        names = ",".join(f"l{i + 1}" for i in range(N_GAINS[args.observer]))
        raise UsageError(f"--observer {args.observer} needs --gains {names} (or --tuning digital)")
    if args.observer in N_GAINS and len(args.gains) != N_GAINS[args.observer]:
        raise UsageError(
            f"--observer {args.observer} takes {N_GAINS[args.observer]} gains, got "
            f"{len(args.gains)}: {','.join(f'{g:g}' for g in args.gains)}"
        )
    for opt in ("lambda1", "lambda2", "dt", "duration"):
        if getattr(args, opt) is None:
            raise UsageError(
                f"--{opt.replace('_', '-')} is required"
                + ("" if opt == "duration" else " (or a --plant FILE.toml that sets it)")
            )
    _check_samples(args.duration, args.dt)
    if (args.u_min is None) != (args.u_max is None) and not _limits_from_file(stage):
        raise UsageError("give both --u-min and --u-max, or neither")
    u_limits = _u_limits(args.u_min, args.u_max)
    if args.integral_rate is not None and args.form != "discrete":
        raise UsageError("--integral-rate needs --form discrete")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TuningWarning)
        controller = make_controller(
            params, args.lambda1, args.lambda2, form=args.form, dt=args.dt,
            integral_rate=args.integral_rate, u_limits=u_limits,
        )  # fmt: skip
    ukf = args.observer == "ukf"
    observer = ObserverSpec.of(args.observer, None if ukf else args.gains, udot_max=args.udot_max)
    return _request(args, stage, (params, observer, controller), (reference, true_params), tuning)


def _request(args, stage: Stage, parts: tuple, run: tuple, tuning, **extra) -> SimulateRequest:
    """The request of one run: the loop of ``parts = (params, observer or None,
    controller)`` on ``run = (reference, true_params)`` with the run's options."""
    params, observer, controller = parts
    loop = ClosedLoop(
        params,
        observer,
        controller,
        dt=args.dt,
        delay=args.delay,
        start=ON_REFERENCE if args.start_on_reference else Start(),
        allow_unbounded=args.allow_unbounded,
    )
    return SimulateRequest(
        stage=stage,
        loop=loop,
        reference=run[0],
        duration=args.duration,
        true_params=run[1],
        noise_std=args.noise_std,
        seed=args.seed,
        csv=args.csv,
        json=bool(args.json),
        tuning=tuning,
        options=dict(vars(args)),
        **extra,
    )


def _baseline_request(args: argparse.Namespace, stage: Stage, true_params) -> SimulateRequest:
    """:func:`simulate_request` for ``--controller`` a baseline (no observer)."""
    given = [
        f"--{o.replace('_', '-')}" for o in _OBSERVER_OPTIONS if getattr(args, o) is not None
    ] + (["--form"] if args.form != "continuous" else [])
    if given:
        raise UsageError(
            f"--controller {args.controller} has no observer and no eq. (12) law: drop "
            + ", ".join(given)
        )
    explicit = [o for o in ("kp", "ki", "kd", "tf") if getattr(args, o) is not None]
    pid = args.controller == "pid"
    if explicit and args.phase_margin is not None:
        raise UsageError("give the gains (--kp, --ki) or --phase-margin (the rule), not both")
    want = ["kp", "ki", "kd", "tf"] if pid else ["kp", "ki"]
    if explicit and sorted(explicit) != sorted(want):
        raise UsageError(
            f"--controller {args.controller} with explicit gains needs "
            + ", ".join(f"--{o}" for o in want)
            + f" (got {', '.join('--' + o for o in explicit)})"
        )
    cfg = stage.config
    if cfg is not None:
        args.dt = stage.default(args, "dt", "[sampling]", cfg.dt)
        ctl = cfg.controller
        if ctl is not None and args.u_min is None and args.u_max is None:
            args.u_min = stage.default(args, "u_min", "[controller]", ctl.u_min)
            args.u_max = stage.default(args, "u_max", "[controller]", ctl.u_max)
    reference = _reference(args, stage)
    if args.dt is None:
        raise UsageError("--dt is required (or a --plant FILE.toml that sets it)")
    _check_samples(args.duration, args.dt)
    if (args.u_min is None) != (args.u_max is None) and not _limits_from_file(stage):
        raise UsageError("give both --u-min and --u-max, or neither")
    params = stage.params
    controller = make_baseline(
        params,
        args.dt,
        args.controller,
        reference=reference,
        gains=[getattr(args, o) for o in want] if explicit else None,
        phase_margin=60.0 if args.phase_margin is None else args.phase_margin,
        delay=args.delay,
        u_limits=_u_limits(args.u_min, args.u_max),
        allow_unbounded=args.allow_unbounded,
    )
    analysis = analyze_baseline(controller, params, delay=args.delay)
    parts, run = (params, None, controller), (reference, true_params)
    return _request(args, stage, parts, run, controller.tuning, analysis=analysis)


def _check_samples(duration: float, dt: float) -> None:
    n = duration / dt
    if n < 2:
        raise UsageError(f"--duration {duration:g} s holds fewer than 2 samples of --dt")
    if n > MAX_SAMPLES:
        raise UsageError(
            f"--duration/--dt = {n:.3g} samples exceeds the limit of {MAX_SAMPLES:.0e}"
        )


def run_simulate(args: argparse.Namespace) -> int:
    """Run ``bwdesign simulate``; returns the exit code."""
    req = simulate_request(args)
    target = None
    if req.csv is not None:
        target = prepare_file(req.csv, command="simulate --csv", what="--csv")
    result = simulate(
        req.loop,
        req.reference,
        duration=req.duration,
        true_params=req.true_params,
        noise_std=req.noise_std,
        seed=req.seed,
    )
    if target is not None:
        _write_csv(result, target)
    params, reference, stage, o = req.loop.model, req.reference, req.stage, req.options
    doc = result.to_dict()
    doc["plant"] = params.to_dict()
    doc["reference"] = reference.to_dict()
    doc["observer"] = o["observer"]
    doc["controller"] = o["controller"]
    doc["tuning"] = req.tuning
    if req.analysis is not None:
        doc["nominal_loop"] = req.analysis.to_dict()
        doc["nominal_loop_text"] = req.analysis.describe()
    doc["csv"] = str(target.path) if target else None
    doc["start"] = "on reference" if o["start_on_reference"] else "rest"
    doc["defaults_from_file"] = stage.to_dict()
    if req.json:
        print(dump_json(doc))
    else:
        if stage.note() is not None:
            print(stage.note())
        _print(result, params, reference.describe(), argparse.Namespace(**o), req.analysis)
    ok = result.stable and (req.analysis is None or req.analysis.stable)
    return EXIT_OK if ok else EXIT_NO


def _file_defaults(args: argparse.Namespace, stage: Stage) -> None:
    """Options not given on the command line, from the sections of a --plant FILE.toml."""
    cfg = stage.config
    if cfg is None:
        return
    if args.observer in ("phso", "eso") and args.tuning is None:
        args.gains = stage.default(args, "gains", "[observer]", cfg.gains)
    args.dt = stage.default(args, "dt", "[sampling]", cfg.dt)
    ctl = cfg.controller
    if ctl is not None and args.tuning is None:
        for opt in ("lambda1", "lambda2"):
            setattr(args, opt, stage.default(args, opt, "[controller]", getattr(ctl, opt)))
    if ctl is not None:
        if args.u_min is None and args.u_max is None:
            args.u_min = stage.default(args, "u_min", "[controller]", ctl.u_min)
            args.u_max = stage.default(args, "u_max", "[controller]", ctl.u_max)
    if args.observer == "ukf" and args.udot_max is None and cfg.envelope_spec is not None:
        env = cfg.envelope(allow_unbounded=args.allow_unbounded)
        args.udot_max = stage.default(args, "udot_max", "[envelope]", env.udot_max)


def _tuning(args: argparse.Namespace, params, stage: Stage) -> dict:
    """Set the gains and constants of ``args`` from the digital tuning; what was used, as JSON.

    With a stage file whose ``[uncertainty]`` is finite, the tuning is chosen against
    that box (margins at every corner of its linear part) instead of the default +-2 %.
    """
    box = None if stage.config is None else stage.config.uncertainty
    if box is not None and box.undetermined():
        box = None
    if box is not None:
        stage.used["--tuning"] = "[uncertainty] box"
    tu = digital_tuning(params, args.dt, delay=args.delay, uncertainty=box)
    kw = tu.controller_kwargs(observer=args.observer)
    args.gains = tuple(float(g) for g in kw["gains"])
    args.lambda1, args.lambda2 = float(kw["lambda1"]), float(kw["lambda2"])
    args.form, args.integral_rate = kw["form"], kw["integral_rate"]
    return {
        "kind": args.tuning,
        "observer": args.observer,
        "gains": list(args.gains),
        "lambda1": args.lambda1,
        "lambda2": args.lambda2,
        "form": args.form,
        "integral_rate": args.integral_rate,
        "observer_bandwidth": tu.observer_bandwidth,
        "dt": tu.dt,
        "delay": tu.delay,
        "met": tu.met,
        "mismatch": tu.mismatch,
        "against": "[uncertainty]" if box is not None else "default mismatch",
        "reasoning": tu.reasoning,
    }


def _limits_from_file(stage: Stage) -> bool:
    return "--u-min" in stage.used or "--u-max" in stage.used


def _u_limits(lo: float | None, hi: float | None) -> tuple[float, float] | None:
    if lo is None and hi is None:
        return None
    return (-math.inf if lo is None else lo, math.inf if hi is None else hi)


def _loop_line(args: argparse.Namespace, s: dict) -> str:
    if args.controller == "eq12":
        return (
            f"loop: {args.observer.upper()} observer, eq. (12) {s['controller']['form']} form, "
            f"lambda1 = {args.lambda1:g}, lambda2 = {args.lambda2:g} 1/s, dt = {args.dt:g} s"
        )
    c = s["controller"]
    gains = f"kp = {c['kp']:.6g}, ki = {c['ki']:.6g}" + (
        f", kd = {c['kd']:.6g}, tf = {c['tf']:.6g}" if c["kd"] else ""
    )
    how = c["tuning"]["rule"] if c["tuning"] else "explicit gains"
    return (
        f"loop: {args.controller} baseline on the measured output, no observer, {gains} "
        f"({how}), dt = {args.dt:g} s"
    )


def _print(
    result: SimulationResult,
    params,
    ref_text: str,
    args: argparse.Namespace,
    analysis: BaselineAnalysis | None = None,
) -> None:
    lu, iu = params.length_unit, params.input_unit
    s = result.settings
    print(
        f"plant: {s['plant'] or '(unnamed)'}" + (" (true plant differs)" if s["true_plant"] else "")
    )
    print(f"reference: {ref_text}")
    print(_loop_line(args, s) + (", one-sample delay" if args.delay else ""))
    if analysis is not None:
        print(f"nominal linear loop: {analysis.describe()}")
    if args.start_on_reference:
        x0 = ", ".join(f"{v:.6g}" for v in s["x0"])
        print(
            f"start: on the reference, {'x0' if s['observer'] is None else 'x0 = xhat0'} = "
            f"({x0}), u held before t = 0: "
            f"{s['u_prev']:.6g} {iu}"
        )
    else:
        print(f"start: from rest, x0 = xhat0 = (0, 0, 0), u = 0 {iu} before t = 0")
    if s.get("true_plant"):
        tp = ", ".join(f"{k} = {s['true_plant'][k]:.9g}" for k in MODEL_FIELDS)
        print(f"true plant: {tp}")
    if result.settings.get("u_limits"):
        lo, hi = result.settings["u_limits"]
        print(f"input limits: {lo:g} .. {hi:g} {iu}")
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
    if result.estimation_rmse is not None:
        e1, e2, e3 = result.estimation_rmse
        print(f"estimation RMSE: x1 {e1:.4g} {lu}, x2 {e2:.4g} {lu}/s, x3 {e3:.4g} {lu}")
    if s.get("u_limits"):
        print(f"input saturated {100 * result.saturated_fraction:.3g} % of the time")
