"""The sampled-data closed loop (:func:`simulate`); see :mod:`bwdesign.sim`."""

from __future__ import annotations

import copy
import dataclasses
import math
import sys
from typing import Any

import numpy as np

from ..control.loop import ClosedLoop
from ..errors import InputError
from ..model.params import BoucWenParams
from ..model.plant import discretize, hysteresis_increment
from ..model.references import Reference
from ..observers.sampled import (
    DisturbanceHysteresisObserver,
    ExtendedStateObserver,
    HysteresisObserver,
)
from ..observers.spec import ObserverSpec
from ..validate import SEED, Range, integer, real
from . import kernel_process
from .batch import observer_record
from .kernel import (
    SCALAR,
    BaselineConstants,
    BaselineState,
    LoopConstants,
    LoopState,
    advance,
    advance_baseline,
    correct,
)
from .result import SimulationResult
from .run import Run, disturbance_samples, diverged, finish, kind_label, prepare, sensor_noise
from .run import noise_kind as check_noise_kind

__all__ = ["simulate", "make_observer", "NOISE_STD"]

#: The fast path's step compiled (:func:`bwdesign.sim.compiled.observer_trace`) where the
#: law has no ``hysteresis_jump`` (:func:`_compiled`); ``False``: always the Python-float
#: step of :mod:`bwdesign.sim.kernel` it is tested against (the same floats, 10x slower).
COMPILED_STEP = True
#: Samples from which a run takes the compiled step even where its kernels are not loaded
#: yet: loading numba and the cached kernels costs about 0.4 s and 100 MB once, the Python
#: step runs about 2.4e5 samples/s, the compiled one 3e6.
COMPILE_FROM = 100_000
#: Supported sensor noise std (length unit).
NOISE_STD = Range(0.0, 1e9, unit="length unit")

_BUILTIN = {
    "phso": HysteresisObserver,
    "eso": ExtendedStateObserver,
    "phdo": DisturbanceHysteresisObserver,
}


def make_observer(
    spec: ObserverSpec,
    params: BoucWenParams,
    dt: float,
    *,
    x0: Any = None,
    u_prev: float = 0.0,
    noise_std: float = 0.0,
    allow_unbounded: bool = False,
) -> Any:
    """Build the observer object ``spec`` names (what :func:`simulate`'s generic path runs).

    Parameters
    ----------
    spec : ObserverSpec
        ``"phso"``: :class:`~bwdesign.observers.HysteresisObserver`; ``"eso"``:
        :class:`~bwdesign.observers.ExtendedStateObserver`; ``"phdo"``:
        :class:`~bwdesign.observers.DisturbanceHysteresisObserver` (a 3-vector ``x0``
        starts ``d`` at 0); ``"ukf"``: :class:`bwdesign.observers.ukf.UnscentedObserver`
        with its default noise model (it needs ``spec.udot_max``); ``"custom"``: a copy
        of the object, or what the factory returns for ``(params, dt)``.
    params : BoucWenParams
        The model the observer uses.
    dt : float
        Sample time (s).
    x0 : array_like, shape (3,), optional
        Initial estimate.
    u_prev : float
        Input held before the first sample (input unit).
    noise_std : float
        Sensor noise std (length unit): the UKF's R (0.01 length units for a noise-free
        run: a filter cannot be told that the sensor is perfect).
    """
    if not isinstance(spec, ObserverSpec):
        raise InputError(f"spec must be an ObserverSpec, got {spec!r}")
    if spec.kind == "custom":
        obj = spec.custom
        if hasattr(obj, "predict") and hasattr(obj, "update"):
            return copy.deepcopy(obj)
        obs = obj(params, dt)
        if x0 is not None and hasattr(obs, "reset"):
            obs.reset(x0, u_prev=u_prev)
        return obs
    if spec.kind in _BUILTIN:
        cls = _BUILTIN[spec.kind]
        if x0 is not None and spec.four_state and np.shape(x0) == (3,):
            x0 = np.array([*np.asarray(x0, dtype=float), 0.0])  # d starts at 0
        return cls(params, spec.gains, dt, x0=x0, u_prev=u_prev, allow_unbounded=allow_unbounded)
    from ..observers.ukf import UnscentedObserver

    if spec.udot_max is None:
        raise InputError(
            f"the UKF needs the input-rate envelope udot_max ({params.input_unit}/s): give "
            "ObserverSpec.of('ukf', udot_max=...) (--udot-max on the command line), or a "
            "periodic reference or a step with a rise time to derive it from"
        )
    return UnscentedObserver(
        params,
        dt,
        udot_max=spec.udot_max,
        noise_std=noise_std if noise_std > 0 else 0.01,
        x0=x0,
        u_prev=u_prev,
        allow_unbounded=allow_unbounded,
    )


def _ukf_envelope(loop: ClosedLoop, reference: Reference) -> ClosedLoop:
    """A UKF without ``udot_max`` gets the reference's envelope (margin 1.1) when it has one."""
    if loop.observer.kind != "ukf" or loop.observer.udot_max is not None:
        return loop
    from ..model.envelope import derive_envelope

    try:
        udot = derive_envelope(
            loop.model, reference, margin=1.1, allow_unbounded=loop.allow_unbounded
        ).udot_max
    except InputError:
        return loop  # make_observer says what is missing
    return loop.replace(observer=dataclasses.replace(loop.observer, udot_max=udot))


def simulate(
    loop: ClosedLoop,
    reference: Reference,
    *,
    duration: float,
    true_params: BoucWenParams | None = None,
    noise_std: float = 0.0,
    seed: int = 0,
    window: Any = None,
    fast: bool = True,
    input_disturbance: Any = None,
    noise_kind: Any = "gaussian",
) -> SimulationResult:
    """Simulate the sampled-data tracking loop ``loop`` (see :mod:`bwdesign.sim`).

    Parameters
    ----------
    loop : ClosedLoop
        Model, observer, law, dt, delay, start (:class:`bwdesign.ClosedLoop`).
    reference : Reference
        Trajectory to track.
    duration : float
        Length of the run (s); ``round(duration/dt)`` samples.
    true_params : BoucWenParams, optional
        The simulated plant, when it differs from the loop's model (model mismatch).
    noise_std : float
        Sensor noise std (length unit), Gaussian, white at ``dt``; with
        ``noise_kind="bounded"`` its bound, ``+-noise_std`` at every sample.
    seed : int
        Seed of ``numpy.random.default_rng`` for the noise.
    window : (float, float), optional
        Metrics window (s); default the last two reference periods (or the last half
        of the run for a reference without a period).
    fast : bool
        The built-in observers (PHSO, ESO, PHDO) run the sample step of
        :mod:`bwdesign.sim.kernel`: compiled (:func:`bwdesign.sim.compiled.observer_trace`,
        the same floats to the bit) with the linear law, on Python floats with
        ``hysteresis_jump``; ``fast=False`` (and the UKF, custom observers) call the
        observer and controller objects, which gives the same numbers to rounding.
    input_disturbance : callable or array_like, optional
        A disturbance ``d`` added to the plant's input (its linear part: ``x2' = ... +
        a3 (u + d)``; the hysteresis, the observer and the law see ``u`` only), held
        over each sample: ``d(t)`` called with the sample times, or the ``n`` samples
        (input unit). See :class:`~bwdesign.DisturbanceBound`.
    noise_kind : {"gaussian", "bounded"} or array_like, shape (n,)
        The noise's kind (:data:`bwdesign.sim.run.NOISE_KINDS`): Gaussian, or
        ``+-noise_std`` with a random sign at every sample (a bounded noise at its bound),
        or a pattern: ``n`` values in [-1, 1], the noise ``noise_std`` times them.

    Returns
    -------
    SimulationResult
        Its ``xhat`` is the posterior estimate; the PHDO's (and what its law sees) is
        the lumped ``(x1, x2, x3 + d)``. A baseline loop (no observer) has no estimate:
        ``xhat`` is NaN and ``estimation_rmse`` None.

    Raises
    ------
    InputError, GainError, UnboundedModelError
        Bad arguments (never for a diverging loop).

    Examples
    --------
    >>> from bwdesign import ClosedLoop, ObserverSpec, Sine, make_controller, preset
    >>> p = preset("paper_experiment")
    >>> loop = ClosedLoop(p, ObserverSpec.of("phso", (2286.2, 1208283.0, -6256.75)),
    ...                   make_controller(p, 200, 200, form="discrete", dt=2e-4), dt=2e-4)
    >>> r = simulate(loop, Sine(amplitude=10, offset=10, frequency=5), duration=0.6)
    >>> r.stable and r.metrics.me < 0.05  # um
    True
    """
    run = prepare(loop, reference, duration=duration, true_params=true_params)
    noise_std = real(noise_std, "noise_std", within=NOISE_STD)
    seed = integer(seed, "seed", within=SEED)
    noise_kind = check_noise_kind(noise_kind, (run.n,))
    noise = sensor_noise(noise_std, seed, run.n, noise_kind)
    if run.loop.baseline:
        drawn = (noise, noise_std, seed, kind_label(noise_kind))
        return _simulate_baseline(run, drawn, window, input_disturbance, true_params)
    loop = _ukf_envelope(run.loop, reference)
    start = run.start
    obs = make_observer(
        loop.observer,
        loop.model,
        loop.dt,
        x0=list(start.xhat0),
        u_prev=start.u_prev,
        noise_std=noise_std,
        allow_unbounded=loop.allow_unbounded,
    )
    ctrl = copy.deepcopy(loop.controller)  # its integrator (if any) must not leak between runs
    ctrl.reset()
    ref = run.reference_terms()
    dist = disturbance_samples(input_disturbance, run)
    # the kernel's switches come from the spec's kind: a custom object (even of a built-in
    # class, with its own u_prev) runs on its own methods
    builtin = loop.observer.kind in _BUILTIN
    path = "fast" if (fast and builtin) else "generic"
    if path == "generic":
        rec = _run_generic(run, loop, obs, ctrl, ref, noise, dist)
    elif _compiled(run):  # the same floats as _run_fast (tests/test_simulate.py)
        rec = observer_record(run, noise, dist)
    else:
        rec = _run_fast(run, loop, obs, ctrl, ref, noise, dist)
    m = rec["m"]
    rec = {k: (v[:m] if isinstance(v, np.ndarray) else v) for k, v in rec.items()}
    rec["t"], rec["x_d"] = run.t[:m], ref[0][:m]
    settings = _settings(run, loop, obs, ctrl, noise_std, seed, true_params is not None)
    settings["path"] = path
    if kind_label(noise_kind) != "gaussian":
        settings["noise_kind"] = kind_label(noise_kind)
    if dist is not None:
        settings["input_disturbance_max"] = float(np.max(np.abs(dist)))
    return finish(run, rec, window=window, mode="sampled", settings=settings)


def _simulate_baseline(run: Run, drawn, window, input_disturbance, true_params):
    """:func:`simulate` for a baseline loop: :func:`~bwdesign.sim.kernel.advance_baseline`;
    ``drawn``: the noise samples, their std, seed and kind."""
    loop, n, dt = run.loop, run.n, run.loop.dt
    ctrl = loop.controller
    noise, noise_std, seed, kind = drawn
    noise = noise.tolist()
    ref = run.reference_terms()
    ff = run.baseline_feedforward()
    c = BaselineConstants(loop, ff, ref, SCALAR)
    tp = run.true_params[0]
    c.set_plant(tp, dt)
    c.dist = disturbance_samples(input_disturbance, run)
    x0 = [float(v) for v in run.start.x0]
    s = BaselineState(x0, float(run.start.u_prev), ctrl.start(x0[0], run.start.u_prev, ff[0]))
    X, U, Z = np.empty((n, 3)), np.empty(n), np.empty(n)
    limit = loop.divergence_limit
    w0 = math.sqrt(tp.a1)
    stable, status, m = True, "ok", n
    for k in range(n):
        zk = s.x1 + noise[k]
        X[k, 0], X[k, 1], X[k, 2] = s.x1, s.x2, s.x3
        Z[k] = zk
        try:
            U[k], _ = advance_baseline(c, s, k, zk)
        except OverflowError:  # the hysteresis step of a plant outside the bounded class
            U[k] = math.nan
            stable, status, m = False, f"diverged at t = {(k + 1) * dt:.6g} s: overflow", k + 1
            break
        why = diverged(limit, w0, s.x1, s.x2, s.x3, 0.0, 0.0, 0.0, s.ua)
        if why is not None:
            stable, status, m = False, f"diverged at t = {(k + 1) * dt:.6g} s: {why}", k + 1
            break
    rec = dict(x=X[:m], xhat=np.full((m, 3), np.nan), u=U[:m], z=Z[:m], stable=stable)
    rec.update(status=status, t=run.t[:m], x_d=ref[0][:m])
    params = loop.model
    settings = {
        "plant": params.name,
        "true_plant": tp.to_dict() if true_params is not None else None,
        "length_unit": params.length_unit,
        "input_unit": params.input_unit,
        "reference": run.reference.to_dict(),
        "observer": None,
        "gains": None,
        "controller": ctrl.to_dict(),
        "u_limits": list(ctrl.u_limits) if ctrl.u_limits else None,
        "dt": dt,
        "duration": n * dt,
        "noise_std": noise_std,
        "seed": int(seed),
        "delay": loop.delay,
        "x0": x0,
        "u_prev": run.start.u_prev,
        "path": "baseline",
    }
    if kind != "gaussian":
        settings["noise_kind"] = kind
    if c.dist is not None:
        settings["input_disturbance_max"] = float(np.max(np.abs(c.dist)))
    return finish(run, rec, window=window, mode="sampled", settings=settings)


def _settings(run: Run, loop: ClosedLoop, obs, ctrl, noise_std, seed, mismatch) -> dict:
    """Everything needed to reproduce the run (JSON-safe)."""
    params, start, tp = loop.model, run.start, run.true_params[0]
    gains = loop.observer.gains
    return {
        "plant": params.name,
        "true_plant": tp.to_dict() if mismatch else None,
        "length_unit": params.length_unit,
        "input_unit": params.input_unit,
        "reference": run.reference.to_dict(),
        "observer": getattr(obs, "kind", type(obs).__name__),
        "gains": None if gains is None else list(gains),
        "controller": ctrl.to_dict(),
        "u_limits": list(ctrl.u_limits) if ctrl.u_limits else None,
        "dt": loop.dt,
        "duration": run.n * loop.dt,
        "noise_std": noise_std,
        "seed": int(seed),
        "delay": loop.delay,
        "compensate_delay": loop.compensate_delay,
        "x0": list(start.x0),
        "xhat0": list(start.xhat0),
        "u_prev": start.u_prev,
    }


def _estimate(obs: Any) -> np.ndarray:
    """What the law sees: ``x_lumped`` (x1, x2, x3 + d) when the observer has it, else ``x``."""
    lumped = getattr(obs, "x_lumped", None)
    return np.asarray(obs.x if lumped is None else lumped, dtype=float)


def _run_generic(run: Run, loop: ClosedLoop, obs, ctrl, ref, noise, dist) -> dict[str, Any]:
    """The loop on the observer and controller objects (any observer)."""
    xd_all, vd_all, ad_all = ref
    n, dt, limit = run.n, loop.dt, loop.divergence_limit
    delay, compensate = loop.delay, loop.compensate_delay
    tp = run.true_params[0]
    X, XH, U, Z = np.empty((n, 3)), np.empty((n, 3)), np.empty(n), np.empty(n)
    x = np.array(run.start.x0, dtype=float)
    up = ua = run.start.u_prev  # ua: input applied over the current sample (delay mode)
    w0 = math.sqrt(tp.a1)
    zt = discretize(tp, dt)
    stable, status, m = True, "ok", n
    with np.errstate(all="ignore"):
        for k in range(n):
            zk = float(x[0]) + float(noise[k])
            obs.update(zk)
            xh = _estimate(obs)
            X[k], XH[k], Z[k] = x, xh, zk
            jkw = {"u_prev": up} if ctrl.hysteresis_jump else {}
            if not delay:
                applied = ctrl(xh, (xd_all[k], vd_all[k], ad_all[k]), **jkw)
            else:
                applied = ua
                jkw = {"u_prev": ua} if ctrl.hysteresis_jump else {}
                if not compensate:
                    u_next = ctrl(xh, (xd_all[k], vd_all[k], ad_all[k]), **jkw)
            U[k] = applied
            h = hysteresis_increment(tp, float(x[2]), up, applied)
            ud = applied if dist is None else applied + dist[k]  # kernel.advance's u + d
            x = zt.F @ np.array([x[0], x[1], h]) + zt.g * ud
            try:
                obs.predict(applied)
            except InputError:
                stable, status, m = False, f"diverged at t = {k * dt:.6g} s: observer input", k + 1
                break
            if delay:
                if compensate:
                    r1 = (xd_all[k + 1], vd_all[k + 1], ad_all[k + 1])
                    u_next = ctrl(_estimate(obs), r1, **jkw)
                ua = u_next
            up = applied
            why = diverged(limit, w0, *x, *_estimate(obs), applied if not delay else ua)
            if why is not None:
                stable, status, m = False, f"diverged at t = {(k + 1) * dt:.6g} s: {why}", k + 1
                break
    return dict(x=X, xhat=XH, u=U, z=Z, m=m, stable=stable, status=status)


def _compiled(run: Run) -> bool:
    """Whether the fast path runs compiled: never with ``hysteresis_jump`` (not compiled) or
    without :data:`COMPILED_STEP`; else where the kernels are loaded already (here or in a
    kernel process, :mod:`.kernel_process`) or the run is long (:data:`COMPILE_FROM`)."""
    if run.loop.controller.hysteresis_jump or not COMPILED_STEP:
        return False
    loaded = kernel_process.active() or "bwdesign.sim.compiled" in sys.modules
    return loaded or run.n >= COMPILE_FROM


def _run_fast(run: Run, loop: ClosedLoop, obs, ctrl, ref, noise, dist) -> dict[str, Any]:
    """The loop on Python floats: :mod:`bwdesign.sim.kernel`'s step, one plant."""
    n, dt, limit = run.n, loop.dt, loop.divergence_limit
    tp = run.true_params[0]
    c = LoopConstants(loop, obs.K, ref, SCALAR)
    c.set_plant(tp, dt)
    c.dist = dist
    c.ki, c.cdt = float(ctrl.ki), float(getattr(ctrl, "dt", dt))
    xh = [float(v) for v in obs.x]
    s = LoopState(
        [float(v) for v in run.start.x0],
        xh[:3],
        xh[3] if c.four else 0.0,
        float(run.start.u_prev),
        float(ctrl.q),
    )
    X, XH, U, Z = np.empty((n, 3)), np.empty((n, 3)), np.empty(n), np.empty(n)
    w0 = math.sqrt(tp.a1)
    vlim = limit * w0
    noise_l = noise.tolist()
    stable, status, m = True, "ok", n
    for k in range(n):
        zk = s.x1 + noise_l[k]
        correct(c, s, zk)
        X[k, 0], X[k, 1], X[k, 2] = s.x1, s.x2, s.x3
        XH[k, 0], XH[k, 1], XH[k, 2] = s.h1, s.h2, s.hw
        Z[k] = zk
        U[k], _ = advance(c, s, k)
        if not (
            abs(s.x1) <= limit
            and abs(s.x3) <= limit
            and abs(s.h1) <= limit
            and abs(s.hw) <= limit
            and abs(s.x2) <= vlim
            and abs(s.h2) <= vlim
            and abs(s.ua) < 1e300
        ):
            why = diverged(limit, w0, s.x1, s.x2, s.x3, s.h1, s.h2, s.hw, s.ua)
            why = why or "non-finite state"
            stable, status, m = False, f"diverged at t = {(k + 1) * dt:.6g} s: {why}", k + 1
            break
    return dict(x=X, xhat=XH, u=U, z=Z, m=m, stable=stable, status=status)
