"""The sampled-data closed loop (:func:`simulate`); see :mod:`bwdesign.sim`."""

from __future__ import annotations

import copy
import math
import numbers
import warnings
from typing import Any

import numpy as np

from ..control.controllers import TrackingController, TuningWarning, make_controller, solve_jump
from ..errors import InputError
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_sample_time, discretize, hysteresis_increment
from ..model.references import Reference
from ..observers.gains import as_gains as _as_gains
from ..observers.gains import check_disturbance_gains, check_gains
from ..observers.sampled import (
    DisturbanceHysteresisObserver,
    ExtendedStateObserver,
    HysteresisObserver,
)
from ..validate import SEED, below_nyquist, integer
from .metrics import steady_state_window, tracking_metrics
from .result import SimulationResult

__all__ = ["simulate", "make_observer"]


# -- helpers -------------------------------------------------------------------


def _finite_nonneg(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(f"{name} must be a number, got {type(value).__name__} {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < 0:
        raise InputError(f"{name} must be a finite number >= 0, got {v}")
    return v


def _state(value: Any, name: str) -> np.ndarray:
    x = np.zeros(3) if value is None else np.array(value, dtype=float)
    if x.shape != (3,) or not np.all(np.isfinite(x)):
        raise InputError(f"{name} must be a finite vector of shape (3,), got {value!r}")
    return x


_BUILTIN = {
    "phso": HysteresisObserver,
    "eso": ExtendedStateObserver,
    "phdo": DisturbanceHysteresisObserver,
}


def make_observer(
    kind: Any,
    params: BoucWenParams,
    gains: Any,
    dt: float,
    *,
    x0: Any = None,
    u_prev: float = 0.0,
    noise_std: float = 0.0,
    udot_max: float | None = None,
    allow_unbounded: bool = False,
) -> Any:
    """Build an observer for :func:`simulate`.

    Parameters
    ----------
    kind : {"phso", "eso", "phdo", "ukf"} or callable
        ``"phso"``: :class:`~bwdesign.observers.HysteresisObserver`;
        ``"eso"``: :class:`~bwdesign.observers.ExtendedStateObserver`;
        ``"phdo"``: :class:`~bwdesign.observers.DisturbanceHysteresisObserver` (four gains;
        a 3-vector ``x0`` starts ``d`` at 0);
        ``"ukf"``: :class:`bwdesign.observers.ukf.UnscentedObserver` with its default
        noise model (gains are not used); a callable is a factory
        ``factory(params, dt) -> observer`` returning an object with
        ``predict(u)``, ``update(z)`` and ``x``.
    params : BoucWenParams
        The model the observer uses.
    gains : array_like, shape (3,)
        Continuous gains (PHSO and ESO).
    dt : float
        Sample time (s).
    x0 : array_like, shape (3,), optional
        Initial estimate.
    u_prev : float
        Input held before the first sample (V).
    noise_std : float
        Measurement noise std (length unit), passed to the UKF as its R.
    udot_max : float, optional
        Input-rate envelope (V/s) for the UKF's process noise.
    """
    if callable(kind) and not isinstance(kind, str):
        obs = kind(params, dt)
        if x0 is not None and hasattr(obs, "reset"):
            obs.reset(x0, u_prev=u_prev)
        return obs
    if kind in _BUILTIN:
        cls = _BUILTIN[kind]
        if gains is None:
            names = "l1, l2, l3, l4" if cls._n == 4 else "l1, l2, l3"
            raise InputError(f"the {kind.upper()} needs observer gains {names}")
        if x0 is not None and cls._n == 4 and np.shape(x0) == (3,):
            x0 = np.array([*np.asarray(x0, dtype=float), 0.0])  # d starts at 0
        return cls(params, gains, dt, x0=x0, u_prev=u_prev, allow_unbounded=allow_unbounded)
    if kind == "ukf":
        return _ukf(
            params,
            dt,
            x0=x0,
            u_prev=u_prev,
            noise_std=noise_std,
            udot_max=udot_max,
            allow_unbounded=allow_unbounded,
        )
    raise InputError(
        "observer must be 'phso', 'eso', 'phdo', 'ukf', an observer object or a factory, got "
        f"{kind!r}"
    )


def _ukf(params, dt, *, x0, u_prev, noise_std, udot_max, allow_unbounded):
    """The :class:`bwdesign.UnscentedObserver` with its documented default noise model.

    Its process noise needs the input-rate envelope ``udot_max`` (V/s); its
    measurement noise is the simulated sensor's std, or 0.01 length units for a
    noise-free run (a filter cannot be told that the sensor is perfect).
    """
    from ..observers.ukf import UnscentedObserver

    if udot_max is None:
        raise InputError(
            f"the UKF needs the input-rate envelope udot_max ({params.input_unit}/s): give "
            "udot_max (--udot-max on the command line), or a periodic reference or a step "
            "with a rise time to derive it from"
        )
    return UnscentedObserver(
        params,
        dt,
        udot_max=udot_max,
        noise_std=noise_std if noise_std > 0 else 0.01,
        x0=x0,
        u_prev=u_prev,
        allow_unbounded=allow_unbounded,
    )


def _window(t: np.ndarray, reference: Reference, window: Any) -> tuple[float, float]:
    if window is None:
        return steady_state_window(t, reference.period)
    try:
        w0, w1 = (float(v) for v in window)
    except (TypeError, ValueError):
        raise InputError(f"window must be (t_start, t_end) in s, got {window!r}") from None
    return (w0, w1)


def _finish(
    *,
    t,
    x,
    xhat,
    u,
    xd,
    z,
    reference,
    window,
    stable,
    status,
    mode,
    settings,
) -> SimulationResult:
    e = x[:, 0] - xd
    metrics = None
    est = None
    if t.size:
        win = _window(t, reference, window)
    else:
        win = (math.nan, math.nan)
    if stable and t.size:
        try:
            metrics = tracking_metrics(e, t, win)
            sel = (t >= win[0] - 1e-12) & (t <= win[1] + 1e-12)
            d = xhat[sel] - x[sel]
            est = tuple(float(v) for v in np.sqrt(np.mean(d * d, axis=0)))
        except InputError as err:
            stable, status = False, f"no metrics: {err}"
    return SimulationResult(
        t=t,
        x=x,
        xhat=xhat,
        u=u,
        x_d=xd,
        e=e,
        z=z,
        metrics=metrics,
        window=win,
        estimation_rmse=est,
        stable=stable,
        status=status,
        mode=mode,
        settings=settings,
    )


def _controller(
    params,
    controller,
    lambda1,
    lambda2,
    form,
    dt,
    u_limits,
    estimate_limits,
    jump=False,
    integral_rate=None,
) -> TrackingController:
    if controller is not None:
        if not isinstance(controller, TrackingController):
            raise InputError(
                f"controller must be a TrackingController, got {type(controller).__name__}"
            )
        if lambda1 is not None or lambda2 is not None:
            raise InputError("give either a controller or lambda1/lambda2, not both")
        ctrl = copy.deepcopy(controller)  # its integrator (if any) must not leak between runs
        ctrl.reset()
        return ctrl
    if lambda1 is None or lambda2 is None:
        raise InputError("the tracking law needs lambda1 and lambda2 (1/s), or a controller")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TuningWarning)
        return make_controller(
            params,
            lambda1,
            lambda2,
            form=form,
            dt=dt,
            u_limits=u_limits,
            estimate_limits=estimate_limits,
            hysteresis_jump=jump,
            integral_rate=integral_rate,
        )


# -- sampled-data loop -----------------------------------------------------------


def simulate(
    params: BoucWenParams,
    reference: Reference,
    *,
    dt: float,
    duration: float,
    observer: Any = "phso",
    gains: Any = None,
    lambda1: float | None = None,
    lambda2: float | None = None,
    controller: TrackingController | None = None,
    form: str = "continuous",
    integral_rate: float | None = None,
    u_limits: Any = None,
    estimate_limits: Any = None,
    hysteresis_jump: bool = False,
    true_params: BoucWenParams | None = None,
    noise_std: float = 0.0,
    seed: int = 0,
    delay: bool = False,
    compensate_delay: bool = True,
    x0: Any = None,
    xhat0: Any = None,
    u_prev: float = 0.0,
    window: Any = None,
    udot_max: float | None = None,
    divergence_limit: float = 1e6,
    allow_unbounded: bool = False,
    fast: bool = True,
) -> SimulationResult:
    """Simulate the sampled-data tracking loop (see the module docstring).

    Parameters
    ----------
    params : BoucWenParams
        The model used by the observer and the controller.
    reference : Reference
        Trajectory to track (``Sine``, ``Triangle``, ``Step``).
    dt : float
        Sample time (s).
    duration : float
        Length of the run (s); ``round(duration/dt)`` samples.
    observer : {"phso", "eso", "phdo", "ukf"}, observer object or factory
        An object is deep-copied (the caller's is not advanced); it must have
        ``predict(u)``, ``update(z)`` and ``x``.
    gains : array_like, shape (3,)
        Continuous observer gains (l1 1/s, l2 1/s^2, l3 1/s) for "phso"/"eso";
        (l1, l2, l3, l4) for "phdo", whose recorded estimate ``xhat`` (and what the law
        sees) is the lumped ``(x1, x2, x3 + d)``.
    lambda1, lambda2 : float
        Eq. (12) constants (1/s), unless ``controller`` is given.
    controller : TrackingController, optional
        A ready controller (continuous or discrete form).
    form : {"continuous", "discrete"}
        Which form of eq. (12) to build from ``lambda1, lambda2``.
    integral_rate : float, optional
        Integral action of the discrete form (1/s).
    u_limits : (float, float), optional
        Amplifier limits (V).
    estimate_limits : sequence of three (lo, hi) or None, optional
        Clip the estimate entering the law (anti-peaking).
    hysteresis_jump : bool
        Let the law use the post-jump hysteresis estimate
        (:mod:`bwdesign.control.controllers`); PHSO (or another observer with the
        hysteresis model) only. Ignored when ``controller`` is given (its own
        setting applies).
    true_params : BoucWenParams, optional
        Parameters of the simulated plant, if they differ from ``params``
        (model mismatch).
    noise_std : float
        Measurement noise std (length unit), Gaussian, white at ``dt``.
    seed : int
        Seed of ``numpy.random.default_rng`` for the noise.
    delay : bool
        One-sample computation delay.
    compensate_delay : bool
        With ``delay``, use the one-step prediction in the law.
    x0, xhat0 : array_like, shape (3,), optional
        Initial plant state and estimate (default zeros).
    u_prev : float
        Input held before ``t = 0`` (V), for plant and observer.
    window : (float, float), optional
        Metrics window (s); default the last two reference periods (or the
        last half of the run for a step).
    udot_max : float, optional
        Input-rate envelope (V/s) for the UKF's noise model; by default derived
        from the reference (:func:`bwdesign.model.envelope.derive_envelope`, margin 1.1).
    divergence_limit : float
        |x1|, |x3| (and their estimates) above this many length units, or
        |x2| above ``divergence_limit sqrt(a1)``, count as divergence.
    allow_unbounded : bool
        Accept parameter sets outside the bounded class.
    fast : bool
        Inline the built-in observers and the (linear) law with scalar
        arithmetic; the generic path (``fast=False``) calls the objects and
        gives the same numbers to rounding.

    Returns
    -------
    SimulationResult

    Raises
    ------
    InputError, GainError, UnboundedModelError
        Bad arguments (never for a diverging loop).

    Examples
    --------
    >>> from bwdesign import preset, Sine
    >>> r = simulate(preset("paper_experiment"), Sine(amplitude=10, offset=10, frequency=5),
    ...              dt=2e-4, duration=0.6, gains=(2286.2, 1208283.0, -6256.75),
    ...              lambda1=200, lambda2=200, form="discrete")
    >>> r.stable and r.metrics.me < 0.05  # um
    True
    """
    if not isinstance(params, BoucWenParams):
        raise InputError(f"params must be a BoucWenParams, got {type(params).__name__}")
    if not isinstance(reference, Reference):
        raise InputError(
            "reference must be a bwdesign Reference (Sine, Triangle, Step or a subclass), "
            f"got {reference!r}"
        )
    tp = params if true_params is None else true_params
    if not isinstance(tp, BoucWenParams):
        raise InputError("true_params must be a BoucWenParams")
    require_bounded(params, allow_unbounded)
    require_bounded(tp, allow_unbounded)
    dt = check_sample_time(tp, check_sample_time(params, dt))
    below_nyquist(reference, dt)
    duration = _finite_nonneg(duration, "duration (s)")
    n = int(round(duration / dt))
    if n < 2:
        raise InputError(f"duration {duration:g} s holds fewer than 2 samples of dt = {dt:g} s")
    noise_std = _finite_nonneg(noise_std, "noise_std")
    seed = integer(seed, "seed", within=SEED)
    x0 = _state(x0, "x0")
    xhat0 = _state(xhat0, "xhat0")
    if isinstance(u_prev, bool) or not isinstance(u_prev, numbers.Real):
        raise InputError(f"u_prev must be a number, got {type(u_prev).__name__} {u_prev!r}")
    u_prev = float(u_prev)
    if not math.isfinite(u_prev):
        raise InputError(f"u_prev must be finite, got {u_prev}")
    divergence_limit = float(divergence_limit)
    if not divergence_limit > 0:
        raise InputError("divergence_limit must be > 0")
    ctrl = _controller(
        params,
        controller,
        lambda1,
        lambda2,
        form,
        dt,
        u_limits,
        estimate_limits,
        hysteresis_jump,
        integral_rate,
    )
    if ctrl.hysteresis_jump and observer == "eso":
        raise InputError(
            "hysteresis_jump needs an observer with the hysteresis model (PHSO); the ESO has none"
        )
    if ctrl.hysteresis_jump and (
        observer == "phdo" or isinstance(observer, DisturbanceHysteresisObserver)
    ):
        raise InputError(
            "hysteresis_jump is not implemented for the disturbance observer (PHDO): its law "
            "would need the jump of x3 with d added; use the PHSO or a law without the jump"
        )
    if getattr(ctrl, "dt", dt) != dt:
        raise InputError(f"the discrete controller was built for dt = {ctrl.dt:g} s, not {dt:g} s")
    if isinstance(observer, str) and observer not in ("phso", "eso", "phdo", "ukf"):
        raise InputError(f"observer must be 'phso', 'eso', 'phdo' or 'ukf', got {observer!r}")
    if gains is not None:
        gains = check_disturbance_gains(params, gains) if observer == "phdo" else _as_gains(gains)
    if isinstance(observer, str) and observer in ("phso", "eso", "phdo"):
        if gains is None:
            names = "l1, l2, l3, l4" if observer == "phdo" else "l1, l2, l3"
            raise InputError(f"the {observer.upper()} needs observer gains {names}")
        if observer != "phdo":
            check_gains(params, gains)

    if observer == "ukf" and udot_max is None:
        from ..model.envelope import derive_envelope

        try:
            udot_max = derive_envelope(
                params, reference, margin=1.1, allow_unbounded=allow_unbounded
            ).udot_max
        except InputError:
            udot_max = None  # make_observer says what is missing
    if isinstance(observer, str) or (callable(observer) and not hasattr(observer, "predict")):
        obs = make_observer(
            observer,
            params,
            gains,
            dt,
            x0=xhat0,
            u_prev=u_prev,
            noise_std=noise_std,
            udot_max=udot_max,
            allow_unbounded=allow_unbounded,
        )
    else:
        if not (hasattr(observer, "predict") and hasattr(observer, "update")):
            raise InputError("observer object must have predict(u), update(z) and x")
        obs = copy.deepcopy(observer)
    kind = getattr(obs, "kind", type(obs).__name__)

    t = np.arange(n) * dt
    t_ref = np.arange(n + 1) * dt
    xd_all, vd_all, ad_all = (np.asarray(a, dtype=float) for a in reference.evaluate(t_ref))
    rng = np.random.default_rng(seed)
    noise = noise_std * rng.standard_normal(n) if noise_std > 0 else np.zeros(n)

    settings = {
        "plant": params.name,
        "true_plant": tp.to_dict() if true_params is not None else None,
        "length_unit": params.length_unit,
        "input_unit": params.input_unit,
        "reference": reference.to_dict(),
        "observer": kind,
        "gains": None if gains is None else gains.tolist(),
        "controller": ctrl.to_dict(),
        "u_limits": list(ctrl.u_limits) if ctrl.u_limits else None,
        "dt": dt,
        "duration": n * dt,
        "noise_std": noise_std,
        "seed": int(seed),
        "delay": bool(delay),
        "compensate_delay": bool(compensate_delay),
        "x0": x0.tolist(),
        "xhat0": xhat0.tolist(),
        "u_prev": u_prev,
    }
    builtin = type(obs) in tuple(_BUILTIN.values())
    runner = _run_fast if (fast and builtin) else _run_generic
    rec = runner(
        params=params,
        tp=tp,
        obs=obs,
        ctrl=ctrl,
        dt=dt,
        n=n,
        ref=(xd_all, vd_all, ad_all),
        noise=noise,
        x0=x0,
        u_prev=u_prev,
        delay=bool(delay),
        compensate=bool(compensate_delay),
        limit=divergence_limit,
    )
    m = rec["m"]
    settings["path"] = "fast" if runner is _run_fast else "generic"
    return _finish(
        t=t[:m],
        x=rec["x"][:m],
        xhat=rec["xhat"][:m],
        u=rec["u"][:m],
        xd=xd_all[:m],
        z=rec["z"][:m],
        reference=reference,
        window=window,
        stable=rec["stable"],
        status=rec["status"],
        mode="sampled",
        settings=settings,
    )


def _diverged(limit, w0, x1, x2, x3, xh1, xh2, xh3, u) -> str | None:
    vals = (x1, x2, x3, xh1, xh2, xh3, u)
    if not all(math.isfinite(v) for v in vals):
        return "non-finite state"
    if max(abs(x1), abs(x3), abs(xh1), abs(xh3)) > limit:
        return f"displacement or hysteresis state beyond {limit:g}"
    if max(abs(x2), abs(xh2)) > limit * w0:
        return f"velocity beyond {limit * w0:g}"
    return None


def _estimate(obs: Any) -> np.ndarray:
    """What the law sees: ``x_lumped`` (x1, x2, x3 + d) when the observer has it, else ``x``."""
    lumped = getattr(obs, "x_lumped", None)
    return np.asarray(obs.x if lumped is None else lumped, dtype=float)


def _run_generic(*, params, tp, obs, ctrl, dt, n, ref, noise, x0, u_prev, delay, compensate, limit):
    xd_all, vd_all, ad_all = ref
    X = np.empty((n, 3))
    XH = np.empty((n, 3))
    U = np.empty(n)
    Z = np.empty(n)
    x = x0.copy()
    up = u_prev
    ua = u_prev  # input applied over the current sample (delay mode)
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
                u = ctrl(xh, (xd_all[k], vd_all[k], ad_all[k]), **jkw)
                applied = u
            else:
                applied = ua
                jkw = {"u_prev": ua} if ctrl.hysteresis_jump else {}
                if not compensate:
                    u_next = ctrl(xh, (xd_all[k], vd_all[k], ad_all[k]), **jkw)
            U[k] = applied
            h = hysteresis_increment(tp, float(x[2]), up, applied)
            x = zt.F @ np.array([x[0], x[1], h]) + zt.g * applied
            try:
                obs.predict(applied)
            except InputError:
                stable, status, m = False, f"diverged at t = {k * dt:.6g} s: observer input", k + 1
                break
            if delay:
                if compensate:
                    u_next = ctrl(
                        _estimate(obs),
                        (xd_all[k + 1], vd_all[k + 1], ad_all[k + 1]),
                        **jkw,
                    )
                ua = u_next
            up = applied
            xhn = _estimate(obs)
            why = _diverged(limit, w0, *x, *xhn, applied if not delay else ua)
            if why is not None:
                stable, status, m = False, f"diverged at t = {(k + 1) * dt:.6g} s: {why}", k + 1
                break
    return dict(x=X, xhat=XH, u=U, z=Z, m=m, stable=stable, status=status)


def _run_fast(*, params, tp, obs, ctrl, dt, n, ref, noise, x0, u_prev, delay, compensate, limit):
    """Scalar-inlined twin of :func:`_run_generic` for the PHSO, the ESO and the PHDO."""
    xd_all, vd_all, ad_all = ref
    Kx, Kr = ctrl.linear_gains()
    ff = Kr[0] * xd_all + Kr[1] * vd_all + Kr[2] * ad_all
    integral = ctrl.integral_rate is not None
    ki = float(ctrl.ki)
    q = float(ctrl.q)
    cdt = float(getattr(ctrl, "dt", dt))
    xd_l = xd_all.tolist()
    kx1, kx2, kx3 = (float(v) for v in Kx)
    ulo, uhi = ctrl.u_limits if ctrl.u_limits else (-math.inf, math.inf)
    if ctrl.estimate_limits:
        (c1l, c1h), (c2l, c2h), (c3l, c3h) = ctrl.estimate_limits
        clip = True
    else:
        clip = False
    zt = discretize(tp, dt)
    zm = discretize(params, dt)
    (p11, p12, p13), (p21, p22, p23) = zt.F[0], zt.F[1]
    pg1, pg2 = float(zt.g[0]), float(zt.g[1])
    (m11, m12, m13), (m21, m22, m23) = zm.F[0], zm.F[1]
    mg1, mg2 = float(zm.g[0]), float(zm.g[1])
    four = type(obs) is DisturbanceHysteresisObserver
    K1, K2, K3 = (float(v) for v in obs.K[:3])
    K4 = float(obs.K[3]) if four else 0.0
    phso = type(obs) in (HysteresisObserver, DisturbanceHysteresisObserver)
    H = hysteresis_increment
    X = np.empty((n, 3))
    XH = np.empty((n, 3))
    U = np.empty(n)
    Z = np.empty(n)
    x1, x2, x3 = (float(v) for v in x0)
    h1, h2, h3 = (float(v) for v in obs.x[:3])
    hd = float(obs.x[3]) if four else 0.0
    up = float(u_prev)  # plant: input held over the previous sample
    upo = float(obs.u_prev)  # observer's idea of it
    ua = float(u_prev)
    w0 = math.sqrt(tp.a1)
    vlim = limit * w0
    noise_l = noise.tolist()
    ff_l = ff.tolist()
    stable, status, m = True, "ok", n

    jump = ctrl.hysteresis_jump

    def law(a, b, c, i, uprev):
        nonlocal q
        if clip:
            a = min(max(a, c1l), c1h)
            b = min(max(b, c2l), c2h)
            c = min(max(c, c3l), c3h)
        f = ff_l[i] + ki * q
        if jump:
            v = solve_jump(params, f + kx1 * a + kx2 * b, kx3, c, uprev)
        else:
            v = f + kx1 * a + kx2 * b + kx3 * c
        if integral:
            q += cdt * (a - xd_l[i])
        return min(max(v, ulo), uhi)

    for k in range(n):
        zk = x1 + noise_l[k]
        r = zk - h1
        h1 += K1 * r
        h2 += K2 * r
        h3 += K3 * r
        if four:
            hd += K4 * r
            hw = h3 + hd
        else:
            hw = h3
        X[k, 0], X[k, 1], X[k, 2] = x1, x2, x3
        XH[k, 0], XH[k, 1], XH[k, 2] = h1, h2, hw
        Z[k] = zk
        if not delay:
            applied = law(h1, h2, hw, k, up)
        else:
            applied = ua
            if not compensate:
                u_next = law(h1, h2, hw, k, ua)
        U[k] = applied
        # plant
        hh = H(tp, x3, up, applied)
        x1, x2, x3 = (
            p11 * x1 + p12 * x2 + p13 * hh + pg1 * applied,
            p21 * x1 + p22 * x2 + p23 * hh + pg2 * applied,
            hh,
        )
        # observer predict
        g3 = H(params, h3, upo, applied) if phso else h3
        gw = g3 + hd if four else g3
        h1, h2, h3 = (
            m11 * h1 + m12 * h2 + m13 * gw + mg1 * applied,
            m21 * h1 + m22 * h2 + m23 * gw + mg2 * applied,
            g3,
        )
        hw = h3 + hd if four else h3
        if delay:
            if compensate:
                u_next = law(h1, h2, hw, k + 1, applied)
            ua = u_next
        up = upo = applied
        if not (
            abs(x1) <= limit
            and abs(x3) <= limit
            and abs(h1) <= limit
            and abs(hw) <= limit
            and abs(x2) <= vlim
            and abs(h2) <= vlim
            and abs(ua) < 1e300
        ):
            why = _diverged(limit, w0, x1, x2, x3, h1, h2, hw, ua) or "non-finite state"
            stable, status, m = False, f"diverged at t = {(k + 1) * dt:.6g} s: {why}", k + 1
            break
    return dict(x=X, xhat=XH, u=U, z=Z, m=m, stable=stable, status=status)
