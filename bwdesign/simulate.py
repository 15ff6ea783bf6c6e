"""Closed-loop simulation: plant, observer and tracking controller.

Two paths:

- :func:`simulate`, the **sampled-data loop** a digital controller runs. The
  plant is the exact ZOH model (:mod:`bwdesign.plant`); observer and
  controller run at ``dt``. Per sample ``k``::

      z_k  = y(t_k) + n_k                      (seeded Gaussian noise, std in length units)
      observer.update(z_k)                     -> xhat_post(t_k)
      u_k  = controller(xhat_post, ref(t_k))   (clipped to u_limits)
      plant: hysteresis jump u_{k-1} -> u_k at t_k, then u_k held to t_{k+1}
      observer.predict(u_k)                    -> xhat_prior(t_{k+1})

  With ``delay=True`` (one-sample computation delay) the input computed at
  ``t_k`` is applied over ``[t_{k+1}, t_{k+2})``; the observer is always
  driven with the input the plant actually receives. With
  ``compensate_delay=True`` (default) the law uses the one-step prediction
  ``xhat_prior(t_{k+1})`` and ``ref(t_{k+1})``, as a careful implementation
  would; with ``False`` it uses the stale posterior.

- :func:`simulate_continuous`, the **continuous-time loop** of the paper's
  Section 4.2 (eq. 12 with the continuous observers eq. 3 / eq. 21), solved
  with a stiff method (``solve_ivp``, Radau by default, ``max_step``
  control). The PHSO needs ``u'`` while ``u`` itself depends on the
  estimate, whose x3 derivative depends on ``u'``: an implicit relation.
  It is solved *exactly*: with ``c = a1/a3`` (the law's weight on x3hat)
  and ``kappa(s, h) = alpha - beta s h - gamma |h|``::

      u' = A + c phi(u', x3hat) = A + c kappa(sign u', x3hat) u'
      =>  u' = A / (1 - c kappa(sign A, x3hat))

  where ``A`` collects every other term of ``d/dt`` eq. (12). The solution is
  unique when ``c kappa < 1`` on both branches (0.67 at most for the paper's
  simulation set, 0.63 for the experiment set); otherwise an error says the
  relation is ill-posed. This adds no dynamics, unlike an amplifier model,
  which would put an extra pole into a loop whose fast pole is at
  ``-lambda1 = -2.2e6`` rad/s and would have to be faster still to stay
  invisible. An amplifier state is available (``amplifier_bandwidth``, rad/s:
  ``u' = wc (u_cmd - u)``) for comparison. Jumps of ``u`` (triangle corners,
  steps: the law contains ``x_d'``) are applied as exact hysteresis jumps
  between integration segments.

Both return a :class:`SimulationResult`. A loop that diverges (non-finite or
huge states) is reported as ``stable = False`` with the record up to the
divergence; it never raises.
"""

from __future__ import annotations

import copy
import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import InputError
from .metrics import Metrics, steady_state_window, tracking_metrics
from .observers import (
    ExtendedStateObserver,
    HysteresisObserver,
    _as_gains,
    check_gains,
)
from .params import BoucWenParams, require_bounded
from .plant import _check_dt, discretize, hysteresis_increment
from .references import Reference, Triangle
from .tracking import TrackingController, TuningWarning, make_controller, solve_jump

__all__ = ["SimulationResult", "simulate", "simulate_continuous", "make_observer"]

STATE_NAMES = ("x1", "x2", "x3")


@dataclass(frozen=True)
class SimulationResult:
    """Record of a closed-loop run.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times (s).
    x : ndarray, shape (N, 3)
        True state at ``t`` (x1 length unit, x2 length unit/s, x3 length unit).
    xhat : ndarray, shape (N, 3)
        Estimate at ``t`` (the posterior, after the measurement at ``t``).
    u : ndarray, shape (N,)
        Input applied from ``t`` (V).
    x_d : ndarray, shape (N,)
        Reference (length unit).
    e : ndarray, shape (N,)
        Tracking error ``x1 - x_d`` (length unit).
    z : ndarray, shape (N,)
        Measured displacement (with noise); equal to x1 for the continuous path.
    metrics : Metrics or None
        MAXE, ME, RMSE of ``e`` over ``window``; None if the loop diverged.
    window : (float, float)
        Steady-state window (s): by default the last two reference periods.
    estimation_rmse : tuple of 3 floats or None
        RMS of ``xhat - x`` per state over the window.
    stable : bool
        False if the run diverged.
    status : str
        ``"ok"`` or what diverged and when.
    mode : str
        ``"sampled"`` or ``"continuous"``.
    settings : dict
        Everything needed to reproduce the run (JSON-safe).
    """

    t: np.ndarray
    x: np.ndarray
    xhat: np.ndarray
    u: np.ndarray
    x_d: np.ndarray
    e: np.ndarray
    z: np.ndarray
    metrics: Metrics | None
    window: tuple[float, float]
    estimation_rmse: tuple[float, float, float] | None
    stable: bool
    status: str
    mode: str
    settings: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("t", "x", "xhat", "u", "x_d", "e", "z"):
            arr = np.array(getattr(self, name), dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def length_unit(self) -> str:
        return self.settings.get("length_unit", "um")

    @property
    def saturated_fraction(self) -> float:
        """Fraction of samples at a ``u_limits`` bound (0 without limits)."""
        lim = self.settings.get("u_limits")
        if not lim or self.u.size == 0:
            return 0.0
        lo, hi = lim
        return float(np.mean((self.u <= lo) | (self.u >= hi)))

    def to_dict(self, *, series: bool = False) -> dict[str, Any]:
        """JSON-ready summary; ``series=True`` adds the time series."""
        lu = self.length_unit
        doc: dict[str, Any] = {
            "mode": self.mode,
            "stable": self.stable,
            "status": self.status,
            "length_unit": lu,
            "metrics": None
            if self.metrics is None
            else {"maxe": self.metrics.maxe, "me": self.metrics.me, "rmse": self.metrics.rmse},
            "window": list(self.window),
            "window_samples": None if self.metrics is None else self.metrics.samples,
            "estimation_rmse": None
            if self.estimation_rmse is None
            else dict(zip(STATE_NAMES, self.estimation_rmse, strict=True)),
            "estimation_rmse_units": {"x1": lu, "x2": f"{lu}/s", "x3": lu},
            "u_range": [float(self.u.min()), float(self.u.max())] if self.u.size else None,
            "saturated_fraction": self.saturated_fraction,
            "samples": int(self.t.size),
            "settings": self.settings,
        }
        if series:
            doc["series"] = {
                "t": self.t.tolist(),
                "x": self.x.tolist(),
                "xhat": self.xhat.tolist(),
                "u": self.u.tolist(),
                "x_d": self.x_d.tolist(),
                "e": self.e.tolist(),
                "z": self.z.tolist(),
            }
        return doc

    def plot(self, **kwargs: Any) -> Any:
        """Plot the run (see :func:`bwdesign.plotting.plot_simulation`); returns (fig, axes)."""
        from . import plotting

        return plotting.plot_simulation(self, **kwargs)


# -- helpers -------------------------------------------------------------------


def _finite_nonneg(value: Any, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v < 0:
        raise InputError(f"{name} must be a finite number >= 0, got {v}")
    return v


def _state(value: Any, name: str) -> np.ndarray:
    x = np.zeros(3) if value is None else np.array(value, dtype=float)
    if x.shape != (3,) or not np.all(np.isfinite(x)):
        raise InputError(f"{name} must be a finite vector of shape (3,), got {value!r}")
    return x


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
    kind : {"phso", "eso", "ukf"} or callable
        ``"phso"``: :class:`~bwdesign.observers.HysteresisObserver`;
        ``"eso"``: :class:`~bwdesign.observers.ExtendedStateObserver`;
        ``"ukf"``: :class:`bwdesign.ukf.UnscentedObserver` with its default
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
    if kind in ("phso", "eso"):
        if gains is None:
            raise InputError(f"the {kind.upper()} needs observer gains l1, l2, l3")
        cls = HysteresisObserver if kind == "phso" else ExtendedStateObserver
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
        f"observer must be 'phso', 'eso', 'ukf', an observer object or a factory, got {kind!r}"
    )


def _ukf(params, dt, *, x0, u_prev, noise_std, udot_max, allow_unbounded):
    """The :class:`bwdesign.ukf.UnscentedObserver` with its documented default noise model.

    Its process noise needs the input-rate envelope ``udot_max`` (V/s); its
    measurement noise is the simulated sensor's std, or 0.01 length units for a
    noise-free run (a filter cannot be told that the sensor is perfect).
    """
    from .ukf import UnscentedObserver

    if udot_max is None:
        raise InputError(
            "the UKF needs the input-rate envelope udot_max (V/s); give udot_max or a "
            "periodic reference to derive it from"
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
    observer : {"phso", "eso", "ukf"}, observer object or factory
        An object is deep-copied (the caller's is not advanced); it must have
        ``predict(u)``, ``update(z)`` and ``x``.
    gains : array_like, shape (3,)
        Continuous observer gains (l1 1/s, l2 1/s^2, l3 1/s) for "phso"/"eso".
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
        (:mod:`bwdesign.tracking`); PHSO (or another observer with the
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
        from the reference (:func:`bwdesign.envelope.derive_envelope`, margin 1.1).
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
        raise InputError(f"reference must be a Sine, Triangle or Step, got {reference!r}")
    tp = params if true_params is None else true_params
    if not isinstance(tp, BoucWenParams):
        raise InputError("true_params must be a BoucWenParams")
    require_bounded(params, allow_unbounded)
    require_bounded(tp, allow_unbounded)
    dt = _check_dt(dt)
    duration = _finite_nonneg(duration, "duration (s)")
    n = int(round(duration / dt))
    if n < 2:
        raise InputError(f"duration {duration:g} s holds fewer than 2 samples of dt = {dt:g} s")
    noise_std = _finite_nonneg(noise_std, "noise_std")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise InputError(f"seed must be an integer, got {seed!r}")
    x0 = _state(x0, "x0")
    xhat0 = _state(xhat0, "xhat0")
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
    if getattr(ctrl, "dt", dt) != dt:
        raise InputError(f"the discrete controller was built for dt = {ctrl.dt:g} s, not {dt:g} s")
    if gains is not None:
        gains = _as_gains(gains)
    if isinstance(observer, str) and observer not in ("phso", "eso", "ukf"):
        raise InputError(f"observer must be 'phso', 'eso' or 'ukf', got {observer!r}")
    if isinstance(observer, str) and observer in ("phso", "eso"):
        if gains is None:
            raise InputError(f"the {observer.upper()} needs observer gains l1, l2, l3")
        check_gains(params, gains)

    if observer == "ukf" and udot_max is None:
        from .envelope import derive_envelope

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
    builtin = type(obs) in (HysteresisObserver, ExtendedStateObserver)
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
            xh = np.asarray(obs.x, dtype=float)
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
                        np.asarray(obs.x, dtype=float),
                        (xd_all[k + 1], vd_all[k + 1], ad_all[k + 1]),
                        **jkw,
                    )
                ua = u_next
            up = applied
            xhn = np.asarray(obs.x, dtype=float)
            why = _diverged(limit, w0, *x, *xhn, applied if not delay else ua)
            if why is not None:
                stable, status, m = False, f"diverged at t = {(k + 1) * dt:.6g} s: {why}", k + 1
                break
    return dict(x=X, xhat=XH, u=U, z=Z, m=m, stable=stable, status=status)


def _run_fast(*, params, tp, obs, ctrl, dt, n, ref, noise, x0, u_prev, delay, compensate, limit):
    """Scalar-inlined twin of :func:`_run_generic` for the PHSO and the ESO."""
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
    K1, K2, K3 = (float(v) for v in obs.K)
    phso = type(obs) is HysteresisObserver
    H = hysteresis_increment
    X = np.empty((n, 3))
    XH = np.empty((n, 3))
    U = np.empty(n)
    Z = np.empty(n)
    x1, x2, x3 = (float(v) for v in x0)
    h1, h2, h3 = (float(v) for v in obs.x)
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
        X[k, 0], X[k, 1], X[k, 2] = x1, x2, x3
        XH[k, 0], XH[k, 1], XH[k, 2] = h1, h2, h3
        Z[k] = zk
        if not delay:
            applied = law(h1, h2, h3, k, up)
        else:
            applied = ua
            if not compensate:
                u_next = law(h1, h2, h3, k, ua)
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
        h1, h2, h3 = (
            m11 * h1 + m12 * h2 + m13 * g3 + mg1 * applied,
            m21 * h1 + m22 * h2 + m23 * g3 + mg2 * applied,
            g3,
        )
        if delay:
            if compensate:
                u_next = law(h1, h2, h3, k + 1, applied)
            ua = u_next
        up = upo = applied
        if not (
            abs(x1) <= limit
            and abs(x3) <= limit
            and abs(h1) <= limit
            and abs(h3) <= limit
            and abs(x2) <= vlim
            and abs(h2) <= vlim
            and abs(ua) < 1e300
        ):
            why = _diverged(limit, w0, x1, x2, x3, h1, h2, h3, ua) or "non-finite state"
            stable, status, m = False, f"diverged at t = {(k + 1) * dt:.6g} s: {why}", k + 1
            break
    return dict(x=X, xhat=XH, u=U, z=Z, m=m, stable=stable, status=status)


# -- continuous-time loop -----------------------------------------------------


def _kappa(p: BoucWenParams, s: float, h: float) -> float:
    return p.alpha - p.beta * s * h - p.gamma * abs(h)


def _solve_udot(A: float, c: float, p: BoucWenParams, h: float) -> float:
    """Solve ``v = A + c kappa(sign v, h) v`` for the input rate ``v`` (V/s)."""
    if A == 0.0:
        return 0.0
    s = 1.0 if A > 0 else -1.0
    den = 1.0 - c * _kappa(p, s, h)
    if den <= 0.0:
        raise InputError(
            f"the implicit relation for u' is ill-posed: (a1/a3) dh/du = "
            f"{c * _kappa(p, s, h):.4g} >= 1 at x3hat = {h:.4g}; use amplifier_bandwidth"
        )
    return A / den


def _scalar_reference(reference: Reference):
    """Return ``t -> (r, r')`` with ``r = (x_d, x_d', x_d'')`` at one time, without arrays."""
    from .references import Sine

    if isinstance(reference, Sine):
        A, off = reference.amplitude, reference.offset
        w, ph = 2 * math.pi * reference.frequency, reference.phase

        def sine(tt: float):
            th = w * tt + ph
            s, c = math.sin(th), math.cos(th)
            r = np.array([off + A * s, A * w * c, -A * w * w * s])
            return r, np.array([r[1], r[2], -A * w**3 * c])

        return sine

    def generic(tt: float):
        xd, vd, ad = reference.evaluate(np.array([tt]))
        jk = reference.jerk(np.array([tt]))
        return np.array([xd[0], vd[0], ad[0]]), np.array([vd[0], ad[0], jk[0]])

    return generic


def _breakpoints(reference: Reference, t_end: float) -> list[float]:
    """Times where ``x_d'`` jumps (sharp triangle corners, sharp steps)."""
    out: list[float] = []
    if isinstance(reference, Triangle) and reference.corner_time == 0:
        f = reference.frequency
        t0 = (-0.5 * math.pi - reference.phase) / (2 * math.pi * f)
        half = 0.5 / f
        k0 = math.ceil((0.0 - t0) / half)
        tb = t0 + k0 * half
        while tb < t_end:
            if tb > 0:
                out.append(tb)
            tb += half
    t_step = getattr(reference, "t_step", None)
    if reference.kind == "step" and 0 < t_step < t_end:
        out.append(float(t_step))
    return sorted(out)


def simulate_continuous(
    params: BoucWenParams,
    reference: Reference,
    *,
    duration: float,
    observer: str = "phso",
    gains: Any,
    lambda1: float,
    lambda2: float,
    u_limits: Any = None,
    true_params: BoucWenParams | None = None,
    x0: Any = None,
    xhat0: Any = None,
    u_prev: float = 0.0,
    output_dt: float | None = None,
    method: str = "Radau",
    rtol: float = 1e-8,
    atol: float | None = None,
    max_step: float | None = None,
    amplifier_bandwidth: float | None = None,
    window: Any = None,
    divergence_limit: float = 1e6,
    allow_unbounded: bool = False,
) -> SimulationResult:
    """Continuous-time closed loop (paper Section 4.2), solved with a stiff method.

    Plant eq. (2), observer eq. (3) (``"phso"``) or eq. (21) (``"eso"``),
    controller eq. (12), all in continuous time. ``u'`` is handled exactly by
    solving the implicit relation (module docstring), or through an
    amplifier state when ``amplifier_bandwidth`` (rad/s) is given.

    Parameters
    ----------
    params : BoucWenParams
        Model of observer and controller.
    reference : Reference
    duration : float
        s.
    observer : {"phso", "eso"}
    gains : array_like, shape (3,)
        Continuous observer gains.
    lambda1, lambda2 : float
        Eq. (12) constants (1/s).
    u_limits : (float, float), optional
        Clip u (V); on a bound ``u' = 0``.
    true_params : BoucWenParams, optional
        The simulated plant (model mismatch).
    x0, xhat0 : array_like, shape (3,), optional
        Initial plant state and estimate (default zeros).
    u_prev : float
        Input before ``t = 0`` (V): the hysteresis jumps from it to ``u(0)``.
    output_dt : float, optional
        Spacing of the recorded samples (s); default ``min(period, duration)/5000``.
    method : str
        ``solve_ivp`` method: "Radau" (default), "BDF" or "LSODA".
    rtol, atol : float
        Tolerances; ``atol`` defaults to ``1e-10`` times each state's scale.
    max_step : float, optional
        Largest step (s); default ``output_dt``.
    amplifier_bandwidth : float, optional
        Model the amplifier as ``u' = wc (u_cmd - u)`` (rad/s) instead of solving
        the implicit relation.
    window, divergence_limit, allow_unbounded
        As for :func:`simulate`.

    Returns
    -------
    SimulationResult
    """
    from scipy.integrate import solve_ivp

    if observer not in ("phso", "eso"):
        raise InputError(f"continuous observer must be 'phso' or 'eso', got {observer!r}")
    tp = params if true_params is None else true_params
    require_bounded(params, allow_unbounded)
    require_bounded(tp, allow_unbounded)
    duration = _finite_nonneg(duration, "duration (s)")
    if duration <= 0:
        raise InputError("duration must be > 0 s")
    l = check_gains(params, gains)
    ctrl = _controller(params, None, lambda1, lambda2, "continuous", None, u_limits, None)
    Kx, Kr = ctrl.linear_gains()
    ulo, uhi = ctrl.u_limits if ctrl.u_limits else (-math.inf, math.inf)
    x0 = _state(x0, "x0")
    xhat0 = _state(xhat0, "xhat0")
    if method not in ("Radau", "BDF", "LSODA"):
        raise InputError(f"method must be a stiff solver (Radau, BDF, LSODA), got {method!r}")
    T = reference.period or duration
    if output_dt is None:
        output_dt = min(T, duration) / 5000.0
    output_dt = _check_dt(output_dt)
    if max_step is None:
        max_step = output_dt
    wc = None
    if amplifier_bandwidth is not None:
        wc = float(amplifier_bandwidth)
        if not math.isfinite(wc) or wc <= 0:
            raise InputError(f"amplifier_bandwidth must be > 0 rad/s, got {amplifier_bandwidth}")
    phso = observer == "phso"
    a1, a2, a3 = params.a1, params.a2, params.a3
    c = Kx[2]  # a1/a3
    l1, l2, l3 = (float(v) for v in l)

    ref3 = _scalar_reference(reference)

    def u_cmd(xh: np.ndarray, r: np.ndarray) -> float:
        return float(Kx @ xh + Kr @ r)

    seg = [0.0, duration]  # the open segment being integrated (reference one-sided there)

    def rhs(tt: float, y: np.ndarray) -> np.ndarray:
        x = y[:3]
        xh = y[3:6]
        eps = 1e-12 * (1.0 + abs(tt))
        r, rdot = ref3(min(max(tt, seg[0] + eps), seg[1] - eps))
        ucmd = u_cmd(xh, r)
        innov = x[0] - xh[0]
        if wc is None:
            u = min(max(ucmd, ulo), uhi)
        else:
            u = y[6]
        d = np.empty_like(y)
        dxh1 = xh[1] + l1 * innov
        dxh2 = -a1 * (xh[0] + xh[2]) - a2 * xh[1] + a3 * u + l2 * innov
        if wc is None:
            if ulo < ucmd < uhi:
                A = Kx[0] * dxh1 + Kx[1] * dxh2 + Kr @ rdot + c * l3 * innov
                if phso:
                    udot = _solve_udot(A, c, params, xh[2])
                else:
                    udot = A
            else:
                udot = 0.0
        else:
            udot = wc * (min(max(ucmd, ulo), uhi) - u)
            d[6] = udot
        d[0] = x[1]
        d[1] = -tp.a1 * (x[0] + x[2]) - tp.a2 * x[1] + tp.a3 * u
        d[2] = _kappa(tp, math.copysign(1.0, udot), x[2]) * udot
        d[3] = dxh1
        d[4] = dxh2
        d[5] = (
            _kappa(params, math.copysign(1.0, udot), xh[2]) * udot if phso else 0.0
        ) + l3 * innov
        return d

    # initial input and hysteresis jump from u_prev
    r0, _ = ref3(0.0)
    u0 = min(max(u_cmd(xhat0, r0), ulo), uhi)
    if wc is None:
        x0 = x0.copy()
        x0[2] = hysteresis_increment(tp, x0[2], u_prev, u0)
        if phso:
            # the law depends on x3hat, which jumps with u: iterate the static fixed point
            for _ in range(50):
                xh = xhat0.copy()
                xh[2] = hysteresis_increment(params, xhat0[2], u_prev, u0)
                u_new = min(max(u_cmd(xh, r0), ulo), uhi)
                if abs(u_new - u0) <= 1e-14 * (1 + abs(u0)):
                    break
                u0 = u_new
            xhat0 = xh
        y0 = np.concatenate([x0, xhat0])
    else:
        y0 = np.concatenate([x0, xhat0, [u_prev]])
    w0 = math.sqrt(tp.a1)
    scale = np.array([1.0, w0, 1.0, 1.0, w0, 1.0] + ([1.0] if wc else []))
    if atol is None:
        atol_v = 1e-10 * scale
    else:
        atol_v = float(atol) * scale

    n_out = int(math.floor(duration / output_dt * (1 + 1e-12))) + 1
    t_out = np.minimum(np.arange(n_out) * output_dt, duration)
    bps = _breakpoints(reference, duration) if wc is None else []
    edges = [0.0, *bps, duration]
    Y = np.full((n_out, y0.size), np.nan)
    stable, status = True, "ok"
    y = y0
    nfev = 0

    def jump(tt: float, y: np.ndarray) -> np.ndarray:
        # u jumps with x_d' at tt: move both hysteresis states along the jump
        eps = 1e-9 * max(1.0, tt)
        rm, _ = ref3(tt - eps)
        rp, _ = ref3(tt + eps)
        um = min(max(u_cmd(y[3:6], rm), ulo), uhi)
        up_ = min(max(u_cmd(y[3:6], rp), ulo), uhi)
        y = y.copy()
        if phso:
            for _ in range(50):
                xh3 = hysteresis_increment(params, y[5], um, up_)
                yy = y.copy()
                yy[5] = xh3
                new = min(max(u_cmd(yy[3:6], rp), ulo), uhi)
                if abs(new - up_) <= 1e-14 * (1 + abs(up_)):
                    break
                up_ = new
            y[5] = xh3
        y[2] = hysteresis_increment(tp, y[2], um, up_)
        return y

    with np.errstate(all="ignore"):
        for i in range(len(edges) - 1):
            ta, tb = edges[i], edges[i + 1]
            if tb <= ta:
                continue
            if i > 0:
                y = jump(ta, y)
            last = i == len(edges) - 2
            sel = (t_out >= ta) & ((t_out <= tb) if last else (t_out < tb))
            t_eval = t_out[sel]
            extra = t_eval.size == 0 or t_eval[-1] < tb
            if extra:
                t_eval = np.append(t_eval, tb)
            seg[0], seg[1] = ta, tb
            try:
                sol = solve_ivp(
                    rhs,
                    (ta, tb),
                    y,
                    method=method,
                    t_eval=t_eval,
                    rtol=rtol,
                    atol=atol_v,
                    max_step=max_step,
                )
            except (InputError, ValueError, ArithmeticError) as err:
                stable, status = False, f"integration failed at t >= {ta:.6g} s: {err}"
                break
            nfev += sol.nfev
            got = sol.y.T[: sol.t.size - 1] if extra else sol.y.T
            idx = np.flatnonzero(sel)[: got.shape[0]]
            Y[idx] = got[: idx.size]
            if sol.status != 0 or sol.t.size < t_eval.size or not np.all(np.isfinite(sol.y)):
                t_fail = sol.t[-1] if sol.t.size else ta
                stable, status = False, f"integration failed at t = {t_fail:.6g} s: {sol.message}"
                break
            y = sol.y[:, -1]
            big = max(abs(y[0]), abs(y[2]), abs(y[3]), abs(y[5]))
            if big > divergence_limit or max(abs(y[1]), abs(y[4])) > divergence_limit * w0:
                stable, status = False, f"diverged before t = {tb:.6g} s"
                break
    ok = np.all(np.isfinite(Y), axis=1)
    m = int(np.argmin(ok)) if not np.all(ok) else n_out
    if m < n_out and stable:
        stable, status = False, "integration stopped early"
    t_rec = t_out[:m]
    X = Y[:m, :3]
    XH = Y[:m, 3:6]
    xd, vd, ad = (np.asarray(a, dtype=float) for a in reference.evaluate(t_rec))
    if wc is None:
        U = np.clip(XH @ Kx + Kr[0] * xd + Kr[1] * vd + Kr[2] * ad, ulo, uhi)
    else:
        U = Y[:m, 6]
    settings = {
        "plant": params.name,
        "true_plant": tp.to_dict() if true_params is not None else None,
        "length_unit": params.length_unit,
        "reference": reference.to_dict(),
        "observer": observer,
        "gains": l.tolist(),
        "controller": ctrl.to_dict(),
        "u_limits": list(ctrl.u_limits) if ctrl.u_limits else None,
        "duration": duration,
        "output_dt": output_dt,
        "method": method,
        "rtol": rtol,
        "atol_scale": float(atol_v[0]),
        "max_step": max_step,
        "udot": "implicit" if wc is None else f"amplifier state, {wc:g} rad/s",
        "x0": list(map(float, y0[:3])),
        "xhat0": list(map(float, y0[3:6])),
        "u_prev": float(u_prev),
        "rhs_evaluations": int(nfev),
    }
    return _finish(
        t=t_rec,
        x=X,
        xhat=XH,
        u=U,
        xd=xd,
        z=X[:, 0].copy(),
        reference=reference,
        window=window,
        stable=stable,
        status=status,
        mode="continuous",
        settings=settings,
    )
