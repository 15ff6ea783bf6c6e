"""Output-feedback tracking controller of paper eq. (12), and its sampled-data form.

The law (paper eq. 12), with the observer's estimate ``xhat`` and the
reference ``(x_d, x_d', x_d'')``::

    u = (1/a3) [ x_d'' + a1 (x1hat + x3hat) + a2 x2hat
                 - lambda1 e_delta - lambda2 (lambda1 e + e_delta) ]
    e = x1hat - x_d,   e_delta = x2hat - x_d'

With exact estimates it cancels the plant's stiffness, damping and
hysteresis and leaves ``e'' + (lambda1 + lambda2) e' + lambda1 lambda2 e = 0``:
tracking-error poles at ``-lambda1`` and ``-lambda2`` (rad/s). Rewritten, it
is a feedforward plus a state feedback on the error::

    u = u_ff + (a1/a3) x3hat + k1 e + k2 e_delta,
    u_ff = (x_d'' + a1 x_d + a2 x_d') / a3,
    k1 = (a1 - lambda1 lambda2) / a3,   k2 = (a2 - lambda1 - lambda2) / a3.

Two forms are provided:

- :class:`TrackingController` (``form = "continuous"``): eq. (12) verbatim.
  Used by the paper's continuous simulations, and in a sampled loop it is the
  law "as printed" evaluated every ``dt`` with the result held (zero-order
  hold). Held over a sample, the cancellation term ``a1 x1hat`` lags the
  plant's spring force by ``dt/2`` on average, which acts as an extra velocity
  feedback ``a1 dt/2`` (16 1/s for the paper's stage at 0.2 ms): the printed
  law is *not* what runs on a digital controller unless ``a1 dt`` is small
  against ``lambda1 + lambda2``. See :mod:`bwdesign.control`.
- :class:`DiscreteTrackingController` (``form = "discrete"``): the sampled
  form of the same design. ``(k1, k2)`` are placed on the exact ZOH model so
  the sampled error poles are ``exp(-lambda1 dt)`` and ``exp(-lambda2 dt)``;
  the hysteresis term ``(a1/a3) x3hat`` cancels x3 exactly under ZOH (x3 and u
  enter the plant through the same column); the feedforward is evaluated at
  the middle of the hold interval (``t_k + dt/2``, from the Taylor expansion of
  the reference triple), which removes the half-sample lag to O(dt^3). As
  ``dt -> 0`` it tends to eq. (12).

Hysteresis jump (sampled loops with the PHSO). Under ZOH the input ``u_k``
makes the hysteresis jump at ``t_k`` from ``x3`` to ``H(x3, u_{k-1}, u_k)``
(:func:`bwdesign.model.plant.hysteresis_increment`), and that post-jump value is
what the plant feels over the whole hold interval. Eq. (12) evaluated on the
posterior estimate cancels the *pre*-jump value: one sample late, which
leaves an error of order ``a1 dh/du du/dt dt / lambda^2`` (0.04 um for the
Table 2 sine at lambda = 200). With ``hysteresis_jump=True`` and the
previous input passed as ``u_prev``, the law solves the scalar implicit
equation ``u = u0 + (a1/a3) H(x3hat, u_prev, u)`` (monotone because
``(a1/a3) dh/du < 1``; Newton, bisection fallback): the sampled analogue of
solving the implicit relation for ``u'`` in continuous time. It needs the
hysteresis model, so it is meaningful with the PHSO only.

Saturation. ``u_limits = (u_min, u_max)`` (V) clips the output, as a real
amplifier does. The observer must then be driven with the *clipped* value
(that is what the plant receives), which :func:`bwdesign.sim.simulate`
does. ``estimate_limits`` clips the estimate before it enters the law: the
standard remedy against observer peaking (Khalil), which keeps a transient
estimate outside the operating range from producing a huge control.

On ``lambda2 > 3/2``: the paper needs it for its Lyapunov bound (18), which
spends ``3/2 sigma^2`` on three Young inequalities. It is sufficient, not
necessary: the linear loop is stable for every ``lambda1, lambda2 > 0`` with
a converged observer. bwdesign therefore rejects ``lambda1 <= 0`` or
``lambda2 <= 0`` (:class:`~bwdesign.errors.GainError`) and only *warns*
(:class:`TuningWarning`) when ``0 < lambda2 <= 3/2``: the paper's proof does
not cover that tuning, but :mod:`bwdesign.control` can still certify the loop.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import GainError, InputError, TuningWarning
from ..model.params import BoucWenParams
from ..model.plant import check_dt, discretize, hysteresis_increment
from ..validate import LAMBDA, input_limits, real

__all__ = [
    "TrackingController",
    "DiscreteTrackingController",
    "ControlTerms",
    "TuningWarning",
    "eq12",
    "error_feedback_gains",
    "discrete_error_gains",
    "make_controller",
    "solve_jump",
    "discrete_integral_gains",
]


def eq12(
    params: BoucWenParams,
    lambda1: float,
    lambda2: float,
    xhat: Any,
    xd: Any,
    xd_dot: Any,
    xd_ddot: Any,
) -> Any:
    """Paper eq. (12) as a plain (vectorised) function, without saturation.

    Parameters
    ----------
    params : BoucWenParams
        The model the controller believes in.
    lambda1, lambda2 : float
        Sliding-surface slope (1/s) and reaching gain (1/s).
    xhat : array_like, shape (3,) or (N, 3)
        Estimate (x1 in length unit, x2 in length unit/s, x3 in length unit).
    xd, xd_dot, xd_ddot : float or array_like, shape (N,)
        Reference and its first two derivatives.

    Returns
    -------
    float or ndarray
        Input (V).
    """
    xh = np.asarray(xhat, dtype=float)
    x1, x2, x3 = xh[..., 0], xh[..., 1], xh[..., 2]
    e = x1 - xd
    ed = x2 - xd_dot
    a1, a2, a3 = params.a1, params.a2, params.a3
    u = (xd_ddot + a1 * (x1 + x3) + a2 * x2 - lambda1 * ed - lambda2 * (lambda1 * e + ed)) / a3
    return float(u) if np.ndim(u) == 0 else u


@dataclass(frozen=True)
class ControlTerms:
    """Eq. (12) split into its terms (each already divided by a3, in V).

    Attributes
    ----------
    feedforward : float
        ``x_d''/a3``.
    stiffness : float
        ``a1 x1hat/a3``.
    hysteresis : float
        ``a1 x3hat/a3``.
    damping : float
        ``a2 x2hat/a3``.
    velocity_error : float
        ``-lambda1 e_delta/a3``.
    sliding : float
        ``-lambda2 (lambda1 e + e_delta)/a3``.
    unsaturated : float
        Sum of the terms (V).
    u : float
        After ``u_limits`` (V).
    """

    feedforward: float
    stiffness: float
    hysteresis: float
    damping: float
    velocity_error: float
    sliding: float
    unsaturated: float
    u: float

    def to_dict(self) -> dict[str, float]:
        return dict(self.__dict__)


def _positive(value: Any, name: str) -> float:
    """A rate of the law (1/s) in :data:`bwdesign.validate.LAMBDA`, or ``GainError``."""
    return real(value, f"{name} (1/s)", within=LAMBDA, error=GainError)


def _estimate_limits(limits: Any) -> tuple[tuple[float, float], ...] | None:
    if limits is None:
        return None
    try:
        pairs = tuple(
            (-math.inf, math.inf) if p is None else (float(p[0]), float(p[1])) for p in limits
        )
    except (TypeError, ValueError, IndexError):
        raise InputError(
            "estimate_limits must be three (lo, hi) pairs or None, one per state "
            f"(x1, x2, x3), got {limits!r}"
        ) from None
    if len(pairs) != 3 or any(not lo < hi for lo, hi in pairs):
        raise InputError(
            f"estimate_limits must be three (lo, hi) pairs with lo < hi, got {limits!r}"
        )
    return pairs


def _check_lambdas(lambda1: Any, lambda2: Any) -> tuple[float, float]:
    l1 = _positive(lambda1, "lambda1")
    l2 = _positive(lambda2, "lambda2")
    if l2 <= 1.5:
        warnings.warn(
            f"lambda2 = {l2:g} <= 3/2: outside the paper's Lyapunov proof (eq. 18 needs "
            "lambda2 > 3/2); the linear loop may still be stable, check it with "
            "bwdesign.control.analyze_loop",
            TuningWarning,
            stacklevel=3,
        )
    return l1, l2


def error_feedback_gains(params: BoucWenParams, lambda1: float, lambda2: float) -> np.ndarray:
    """``(k1, k2)`` of eq. (12) on ``(e, e_delta)``: ``((a1 - l1 l2)/a3, (a2 - l1 - l2)/a3)``.

    Units: V per length unit, V per (length unit/s).
    """
    a1, a2, a3 = params.a1, params.a2, params.a3
    return np.array([(a1 - lambda1 * lambda2) / a3, (a2 - lambda1 - lambda2) / a3])


def discrete_error_gains(
    params: BoucWenParams, lambda1: float, lambda2: float, dt: float
) -> np.ndarray:
    """``(k1, k2)`` placing the sampled error poles at ``exp(-lambda1 dt)``, ``exp(-lambda2 dt)``.

    The plant is the exact ZOH model of ``(x1, x2)`` (x3 cancelled): the
    eigenvalues of ``Phi + Gamma [k1, k2]`` are the requested ones.
    Ackermann's formula is evaluated with x2 scaled by ``sqrt(a1)``.

    Parameters
    ----------
    params : BoucWenParams
    lambda1, lambda2 : float
        Continuous-time error poles (1/s), > 0.
    dt : float
        Sample time (s).

    Returns
    -------
    ndarray, shape (2,)
        V per length unit, V per (length unit/s).
    """
    dt = check_dt(dt)
    zoh = discretize(params, dt)
    w0 = math.sqrt(params.a1)
    s = np.array([1.0, 1.0 / w0])
    Phi = s[:, None] * zoh.F[:2, :2] / s[None, :]
    Gam = s * zoh.g[:2]
    W = np.column_stack([Gam, Phi @ Gam])
    z1, z2 = math.exp(-lambda1 * dt), math.exp(-lambda2 * dt)
    pPhi = Phi @ Phi - (z1 + z2) * Phi + z1 * z2 * np.eye(2)
    try:
        row = np.linalg.solve(W.T, np.array([0.0, 1.0]))
    except np.linalg.LinAlgError:
        raise GainError(f"the sampled plant is not controllable at dt = {dt:g} s") from None
    K = row @ pPhi  # u = -K x places the poles
    return -K * s


class TrackingController:
    """Paper eq. (12): output-feedback tracking law on the observer's estimate.

    Parameters
    ----------
    params : BoucWenParams
        The model the controller uses (a1, a2, a3).
    lambda1 : float
        Sliding-surface slope (1/s), > 0.
    lambda2 : float
        Reaching gain (1/s), > 0; the paper asks > 3/2 (a :class:`TuningWarning`
        below that, see the module docstring).
    u_limits : (float, float), optional
        Amplifier limits (V); the output is clipped to them.
    estimate_limits : sequence of three (lo, hi) or None, optional
        Clip each estimate (x1, x2, x3) before it enters the law (anti-peaking).
    hysteresis_jump : bool
        Use the post-jump hysteresis estimate (module docstring); then calls
        must pass ``u_prev``.

    Raises
    ------
    GainError
        ``lambda1`` or ``lambda2`` not a finite positive number.
    InputError
        Malformed limits.

    Notes
    -----
    Calling the controller is a pure function of its arguments, except for
    the discrete form with ``integral_rate``, whose integrator advances on
    every call: call it once per sample, and :meth:`reset` before a new run.

    Examples
    --------
    >>> from bwdesign import preset
    >>> c = TrackingController(preset("paper_experiment"), 1.0, 2.0)
    >>> round(c([0.0, 0.0, 0.0], (0.0, 0.0, 0.0)), 12)
    0.0
    """

    form = "continuous"

    def __init__(
        self,
        params: BoucWenParams,
        lambda1: float,
        lambda2: float,
        *,
        u_limits: Any = None,
        estimate_limits: Any = None,
        hysteresis_jump: bool = False,
    ) -> None:
        if not isinstance(params, BoucWenParams):
            raise InputError(f"params must be a BoucWenParams, got {type(params).__name__}")
        self.params = params
        self.lambda1, self.lambda2 = _check_lambdas(lambda1, lambda2)
        self.u_limits = input_limits(u_limits)
        self.estimate_limits = _estimate_limits(estimate_limits)
        self.hysteresis_jump = bool(hysteresis_jump)
        self.gains = error_feedback_gains(params, self.lambda1, self.lambda2)
        self.integral_rate: float | None = None
        self.ki = 0.0
        self.q = 0.0

    def reset(self) -> None:
        """Clear the integrator (discrete form with ``integral_rate``)."""
        self.q = 0.0

    # -- the law -------------------------------------------------------------
    def _clip_estimate(self, xhat: Any) -> tuple[float, float, float]:
        x1, x2, x3 = (float(v) for v in xhat)
        if self.estimate_limits is not None:
            (l1, h1), (l2, h2), (l3, h3) = self.estimate_limits
            x1, x2, x3 = min(max(x1, l1), h1), min(max(x2, l2), h2), min(max(x3, l3), h3)
        return x1, x2, x3

    def _clip_u(self, u: float) -> float:
        if self.u_limits is not None:
            return min(max(u, self.u_limits[0]), self.u_limits[1])
        return u

    def unsaturated(self, xhat: Any, ref: tuple[float, float, float]) -> float:
        """The law before ``u_limits`` (V); ``ref = (x_d, x_d', x_d'')``."""
        x1, x2, x3 = self._clip_estimate(xhat)
        xd, vd, ad = ref
        p = self.params
        e = x1 - xd
        ed = x2 - vd
        return (
            ad
            + p.a1 * (x1 + x3)
            + p.a2 * x2
            - self.lambda1 * ed
            - self.lambda2 * (self.lambda1 * e + ed)
        ) / p.a3

    def __call__(
        self, xhat: Any, ref: tuple[float, float, float], *, u_prev: float | None = None
    ) -> float:
        """Input ``u`` (V) for the estimate ``xhat`` and ``ref = (x_d, x_d', x_d'')``.

        ``u_prev`` (V), the input held over the previous sample, is required
        when the controller was built with ``hysteresis_jump=True``.
        """
        u = self.unsaturated(xhat, ref)
        if self.hysteresis_jump:
            if u_prev is None:
                raise InputError("hysteresis_jump=True needs u_prev, the previous input (V)")
            x3 = self._clip_estimate(xhat)[2]
            p = self.params
            u = solve_jump(p, u - p.a1 * x3 / p.a3, p.a1 / p.a3, x3, float(u_prev))
        if self.integral_rate is not None:
            self.q += self.dt * (self._clip_estimate(xhat)[0] - float(ref[0]))
        return self._clip_u(u)

    def terms(self, xhat: Any, ref: tuple[float, float, float]) -> ControlTerms:
        """Eq. (12) term by term (for reports and tests)."""
        x1, x2, x3 = self._clip_estimate(xhat)
        xd, vd, ad = ref
        p = self.params
        e, ed = x1 - xd, x2 - vd
        parts = dict(
            feedforward=ad / p.a3,
            stiffness=p.a1 * x1 / p.a3,
            hysteresis=p.a1 * x3 / p.a3,
            damping=p.a2 * x2 / p.a3,
            velocity_error=-self.lambda1 * ed / p.a3,
            sliding=-self.lambda2 * (self.lambda1 * e + ed) / p.a3,
        )
        raw = self.unsaturated(xhat, ref)
        return ControlTerms(**parts, unsaturated=raw, u=self._clip_u(raw))

    def linear_gains(self) -> tuple[np.ndarray, np.ndarray]:
        """The law as ``u = Kx . xhat + Kr . (x_d, x_d', x_d'')`` (no saturation).

        Returns
        -------
        Kx : ndarray, shape (3,)
            V per (length unit, length unit/s, length unit).
        Kr : ndarray, shape (3,)
            V per (length unit, length unit/s, length unit/s^2).
        """
        p = self.params
        k1, k2 = self.gains
        Kx = np.array([k1, k2, p.a1 / p.a3])
        Kr = np.array(
            [self.lambda1 * self.lambda2 / p.a3, (self.lambda1 + self.lambda2) / p.a3, 1 / p.a3]
        )
        return Kx, Kr

    def to_dict(self) -> dict[str, Any]:
        return {
            "form": self.form,
            "lambda1": self.lambda1,
            "lambda2": self.lambda2,
            "u_limits": list(self.u_limits) if self.u_limits else None,
            "estimate_limits": [list(p) for p in self.estimate_limits]
            if self.estimate_limits
            else None,
            "hysteresis_jump": self.hysteresis_jump,
            "integral_rate": self.integral_rate,
            "error_gains": self.gains.tolist(),
        }

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(plant={self.params.name or 'unnamed'!r}, "
            f"lambda1={self.lambda1:g}, lambda2={self.lambda2:g}, u_limits={self.u_limits})"
        )


class DiscreteTrackingController(TrackingController):
    """Sampled-data form of eq. (12) for a loop running at ``dt``.

    ``u_k = u_ff(t_k + dt/2) + (a1/a3) x3hat + k1 e_k + k2 e_delta_k`` with
    ``(k1, k2)`` from :func:`discrete_error_gains` (sampled error poles
    ``exp(-lambda_i dt)``) and the feedforward
    ``u_ff = (x_d'' + a1 x_d + a2 x_d')/a3`` at mid-sample, from the reference
    triple at ``t_k`` by Taylor expansion
    (``x_d + x_d' dt/2 + x_d'' dt^2/8``, ``x_d' + x_d'' dt/2``, ``x_d''``).

    Parameters
    ----------
    params : BoucWenParams
    lambda1, lambda2 : float
        Continuous-time error poles (1/s), > 0.
    dt : float
        Sample time (s).
    integral_rate : float, optional
        Add integral action on the estimated error with a third sampled pole
        at ``exp(-integral_rate dt)`` (1/s).
    u_limits, estimate_limits, hysteresis_jump
        As for :class:`TrackingController`.

    Examples
    --------
    >>> from bwdesign import preset
    >>> c = DiscreteTrackingController(preset("paper_experiment"), 200.0, 200.0, dt=2e-4)
    >>> c.form
    'discrete'
    """

    form = "discrete"

    def __init__(
        self,
        params: BoucWenParams,
        lambda1: float,
        lambda2: float,
        *,
        dt: float,
        integral_rate: float | None = None,
        u_limits: Any = None,
        estimate_limits: Any = None,
        hysteresis_jump: bool = False,
    ) -> None:
        super().__init__(
            params,
            lambda1,
            lambda2,
            u_limits=u_limits,
            estimate_limits=estimate_limits,
            hysteresis_jump=hysteresis_jump,
        )
        self.dt = check_dt(dt)
        if integral_rate is None:
            self.gains = discrete_error_gains(params, self.lambda1, self.lambda2, self.dt)
        else:
            self.integral_rate = _positive(integral_rate, "integral_rate")
            k = discrete_integral_gains(
                params, self.lambda1, self.lambda2, self.integral_rate, self.dt
            )
            self.gains = k[:2]
            self.ki = float(k[2])

    def unsaturated(self, xhat: Any, ref: tuple[float, float, float]) -> float:
        x1, x2, x3 = self._clip_estimate(xhat)
        xd, vd, ad = ref
        p = self.params
        h = 0.5 * self.dt
        xm = xd + vd * h + 0.5 * ad * h * h
        vm = vd + ad * h
        uff = (ad + p.a1 * xm + p.a2 * vm) / p.a3
        k1, k2 = self.gains
        return uff + p.a1 * x3 / p.a3 + k1 * (x1 - xd) + k2 * (x2 - vd) + self.ki * self.q

    def terms(self, xhat: Any, ref: tuple[float, float, float]) -> ControlTerms:
        raise NotImplementedError(
            "the discrete form is not eq. (12) term by term; use unsaturated() or linear_gains()"
        )

    def linear_gains(self) -> tuple[np.ndarray, np.ndarray]:
        p = self.params
        k1, k2 = self.gains
        h = 0.5 * self.dt
        Kx = np.array([k1, k2, p.a1 / p.a3])
        Kr = np.array(
            [
                p.a1 / p.a3 - k1,
                (p.a1 * h + p.a2) / p.a3 - k2,
                (1 + p.a1 * h * h / 2 + p.a2 * h) / p.a3,
            ]
        )
        return Kx, Kr

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        d["dt"] = self.dt
        d["integral_gain"] = self.ki
        return d


def solve_jump(params: BoucWenParams, u0: float, c: float, h: float, u_prev: float) -> float:
    """Solve ``u = u0 + c H(h, u_prev, u)`` for ``u`` (V).

    ``H`` is :func:`bwdesign.model.plant.hysteresis_increment`. The residual
    ``u - u0 - c H`` has slope ``1 - c dh/du``; while ``c dh/du < 1`` the root
    is unique and Newton from ``u0 + c h`` converges in a few steps. Where the
    relation is ill-posed or nearly so (``c dh/du > 0.9``, which happens only
    when the estimate has left the hysteresis range ``|h| <= alpha/(beta +
    gamma)``, e.g. while absorbing a model error) the pre-jump law
    ``u0 + c h`` is returned instead: the jump correction is then not trusted.
    """
    p = params
    naive = u0 + c * h
    v = naive
    for _ in range(30):
        hv = hysteresis_increment(p, h, u_prev, v)
        r = v - u0 - c * hv
        if abs(r) <= 1e-12 * (1.0 + abs(v)):
            return v
        s = 1.0 if v >= u_prev else -1.0
        slope = 1.0 - c * (p.alpha - p.beta * s * hv - p.gamma * abs(hv))
        if slope < 0.1:
            return naive
        v -= r / slope
    return naive


def discrete_integral_gains(
    params: BoucWenParams, lambda1: float, lambda2: float, integral_rate: float, dt: float
) -> np.ndarray:
    """``(k1, k2, ki)`` placing the poles of ``(e, e_delta, q)`` at ``exp(-rate dt)``.

    ``q_{k+1} = q_k + dt e_k`` integrates the error; the closed loop
    ``Phi_a + Gamma_a [k1, k2, ki]`` of the augmented ZOH model gets the
    eigenvalues ``exp(-lambda1 dt)``, ``exp(-lambda2 dt)``,
    ``exp(-integral_rate dt)``.

    Returns
    -------
    ndarray, shape (3,)
        V per length unit, V per (length unit/s), V per (length unit s).
    """
    dt = check_dt(dt)
    zoh = discretize(params, dt)
    w0 = math.sqrt(params.a1)
    s = np.array([1.0, 1.0 / w0, 1.0 / dt])
    Phi = np.zeros((3, 3))
    Phi[:2, :2] = zoh.F[:2, :2]
    Phi[2, 0] = dt
    Phi[2, 2] = 1.0
    Gam = np.array([zoh.g[0], zoh.g[1], 0.0])
    Ps = s[:, None] * Phi / s[None, :]
    Gs = s * Gam
    W = np.column_stack([Gs, Ps @ Gs, Ps @ Ps @ Gs])
    zs = [math.exp(-r * dt) for r in (lambda1, lambda2, integral_rate)]
    c = np.real(np.poly(zs))
    pP = c[0] * Ps @ Ps @ Ps + c[1] * Ps @ Ps + c[2] * Ps + c[3] * np.eye(3)
    try:
        row = np.linalg.solve(W.T, np.array([0.0, 0.0, 1.0]))
    except np.linalg.LinAlgError:
        raise GainError(
            f"the sampled plant with integrator is not controllable at dt = {dt:g}"
        ) from None
    return -(row @ pP) * s


def make_controller(
    params: BoucWenParams,
    lambda1: float,
    lambda2: float,
    *,
    form: str = "continuous",
    dt: float | None = None,
    u_limits: Any = None,
    estimate_limits: Any = None,
    hysteresis_jump: bool = False,
    integral_rate: float | None = None,
) -> TrackingController:
    """Build the controller of the given ``form`` (``"continuous"`` or ``"discrete"``)."""
    kw = dict(u_limits=u_limits, estimate_limits=estimate_limits, hysteresis_jump=hysteresis_jump)
    if form == "continuous":
        if integral_rate is not None:
            raise InputError("integral action is available in the discrete form only")
        return TrackingController(params, lambda1, lambda2, **kw)
    if form == "discrete":
        if dt is None:
            raise InputError("the discrete form of eq. (12) needs the sample time dt (s)")
        return DiscreteTrackingController(
            params, lambda1, lambda2, dt=dt, integral_rate=integral_rate, **kw
        )
    raise InputError(f"controller form must be 'continuous' or 'discrete', got {form!r}")
