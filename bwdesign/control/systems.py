"""Linear analysis of the tracking loop (observer + eq. 12), with python-control.

The loop analysed is the linear part of the closed loop of
:mod:`bwdesign.sim`:

- **plant** (the *true* parameters): ``x1' = x2``,
  ``x2' = -a1 x1 - a2 x2 - a1 x3 + a3 u``, ``y = x1``, with the hysteresis
  state x3 *held* (a constant disturbance; dh/du = 0, as on a saturated branch
  of the hysteresis loop). Sampled at ``dt`` it is the exact ZOH model of
  :func:`bwdesign.model.plant.discretize`.
- **observer** (the *model* parameters): the linear part of eq. (3)/(21),
  ``xhat' = A0 xhat + B u + l (y - x1hat)``; with x3 held the PHSO and the ESO
  have the same linear part, so this analysis does not distinguish them.
  Sampled, it is the predict/update observer of :mod:`bwdesign.observers`
  with the correction ``K = discrete_gains(params, gains, dt)``, run as in
  the simulation: ``update(y_k)``, ``u_k`` from the posterior, ``predict(u_k)``.
- **controller**: eq. (12) (``form = "continuous"``) or its sampled form
  (``form = "discrete"``, :class:`bwdesign.control.controllers.DiscreteTrackingController`),
  ``u = Kx . xhat + Kr . (x_d, x_d', x_d'')``.

With ``estimator = "state"`` the observer is replaced by the true states
(x1, x2, x3): the loop eq. (12) would have with perfect measurements. It
shows what the observer does for robustness: the cancellation ``a1 x1hat``
is exact only if a1 is, and with true states an a1 error of
``lambda1 lambda2 / a1`` (relative) removes all the loop's stiffness, while
with the observer the x3 estimate absorbs the model error (the ESO and PHSO
act as disturbance observers).

Margins are those of the loop broken at the plant input,
``L = -C(s) P(s)`` with ``u = C(s) y`` the controller (observer + law) and
``P`` the plant: the gain margin is reported as the interval of loop gains
``[k_min, k_max]`` for which the closed loop is stable (found from the closed
loop's eigenvalues, so it is right for open-loop unstable controllers too), the
phase margin and crossover from :func:`control.stability_margins` (smallest
over all crossovers), and the delay margin as phase margin / crossover.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams
from ..model.plant import discretize
from ..observers.gains import as_gains, discrete_gains
from .controllers import TrackingController
from .loop import ClosedLoop

__all__ = ["loop_systems", "closed_loop_matrix", "loop_parts"]


_C3 = np.array([1.0, 0.0, 0.0])


@dataclass(frozen=True)
class LoopSystems:
    """State-space pieces of the loop, in scaled coordinates (x2 / sqrt(a1)).

    Attributes
    ----------
    plant : control.StateSpace or None
        u -> y of the true plant (x3 held), continuous or sampled.
    controller : control.StateSpace or None
        y -> u (observer + law); for ``estimator="state"`` the static state
        feedback (input: the plant state).
    loop : control.StateSpace or None
        ``L = -C P`` broken at the plant input.
    A_cl : ndarray
        Closed-loop state matrix (plant states first).
    B_ff : ndarray
        Where a unit of feedforward input ``Kr . r`` enters the closed loop.
    B_int : ndarray
        Where ``-dt x_d`` enters (the integrator; zeros without one).
    ref_gain : ndarray
        ``Kr`` (V per length unit, per length unit/s, per length unit/s^2).
    ref_advance : bool
        Whether the law uses the reference one sample ahead (delay compensation).
    dt : float or None
    """

    plant: Any
    controller: Any
    loop: Any
    A_cl: np.ndarray
    B_ff: np.ndarray
    B_int: np.ndarray
    ref_gain: np.ndarray
    ref_advance: bool
    dt: float | None
    A_in: np.ndarray | None = None

    def with_loop_gain(self, k: float) -> np.ndarray:
        """Closed-loop matrix with the plant input scaled by ``k`` (``A_cl`` is affine in k)."""
        return self.A_cl + (k - 1.0) * self.A_in


def _discrete_controller(F, g, K, Kx, ki, dt, *, delay, compensate, integral):
    """Controller matrices ``(Ac, Bc, Cc, Dc, b_ff, b_int)`` of the sampled observer + law.

    Controller state ``c = [xhat_prior (3), u_applied (if delay), q (if integral)]``,
    input ``y``. Every quantity is a row map over ``[c; y]``.
    """
    nc = 3 + int(delay) + int(integral)
    iu = 3 if delay else None
    iq = nc - 1 if integral else None

    def sel(i):
        r = np.zeros(nc + 1)
        r[i] = 1.0
        return r

    Exp = np.zeros((3, nc + 1))
    Exp[:, :3] = np.eye(3)
    Ey = sel(nc)
    IKC = np.eye(3) - np.outer(K, _C3)
    post = IKC @ Exp + np.outer(K, Ey)
    q_term = ki * sel(iq) if integral else np.zeros(nc + 1)
    b_ff = np.zeros(nc)
    b_int = np.zeros(nc)
    rows: dict[str, np.ndarray] = {}
    if not delay:
        v = post
        u = Kx @ v + q_term
        rows["xp"] = F @ post + np.outer(g, u)
        plant_in = u
        b_ff[:3] = g
    else:
        Eu = sel(iu)
        if compensate:
            rows["xp"] = F @ post + np.outer(g, Eu)
            v = rows["xp"]
        else:
            v = post
            rows["xp"] = F @ post + np.outer(g, Eu)
        rows["u"] = Kx @ v + q_term
        plant_in = Eu
        b_ff[iu] = 1.0
    if integral:
        rows["q"] = sel(iq) + dt * v[0]
        b_int[iq] = 1.0
    nxt = [rows["xp"]]
    if delay:
        nxt.append(rows["u"][None, :])
    if integral:
        nxt.append(rows["q"][None, :])
    M = np.vstack(nxt)
    return M[:, :nc], M[:, nc:], plant_in[None, :nc], plant_in[None, nc:], b_ff, b_int


def loop_systems(
    loop: ClosedLoop,
    *,
    true_params: BoucWenParams | None = None,
    estimator: str = "observer",
    loop_gain: float = 1.0,
    lti: bool = True,
) -> LoopSystems:
    """Build plant, controller, loop transfer and closed-loop matrix.

    Parameters are those of :func:`~bwdesign.control.analysis.analyze_loop`;
    ``loop_gain`` scales the plant input (used to find the gain-margin interval) and
    ``lti=False`` skips building the python-control objects.
    """
    params, ctrl, dt, delay = loop_parts(loop, estimator)
    compensate_delay = loop.compensate_delay
    tp = params if true_params is None else true_params
    Kx, Kr = ctrl.linear_gains()
    ki = ctrl.ki
    integral = ctrl.integral_rate is not None
    w0 = math.sqrt(params.a1)
    s2 = np.array([1.0, 1.0 / w0])  # plant scaling z = S x
    s3 = np.array([1.0, 1.0 / w0, 1.0])
    Kxs = Kx / s3  # u = Kx x = Kxs z
    ts = dt if dt else 0

    # plant (x3 held), true parameters
    if dt is None:
        Ap = np.array([[0.0, 1.0], [-tp.a1, -tp.a2]])
        Bp = np.array([0.0, tp.a3])
    else:
        zt = discretize(tp, dt)
        Ap, Bp = zt.F[:2, :2], zt.g[:2]
    Ap = s2[:, None] * Ap / s2[None, :]
    Bp = s2 * Bp * loop_gain
    Cp = np.array([1.0, 0.0])
    n = 2
    if lti:
        import control  # heavy; only for the LTI objects (bwdesign import stays light)

        P = control.ss(Ap, Bp[:, None], Cp[None, :], 0.0, ts)
    else:
        P = None

    if estimator == "state":
        if delay or integral:
            raise InputError("the state-feedback comparison is defined without delay or integrator")
        return _state_feedback(Ap, Bp, Kxs, Kr, dt, lti)

    l = as_gains(loop.observer.gains)
    if dt is None:
        Ac, Bc, Cc, Dc, b_ff, b_int = _continuous_controller(params, l, s3, Kxs)
        ref_advance = False
        plant_ff = 1.0
    else:
        zm = discretize(params, dt)
        F = s3[:, None] * zm.F / s3[None, :]
        g = s3 * zm.g
        K = s3 * discrete_gains(params, l, dt)
        Ac, Bc, Cc, Dc, b_ff, b_int = _discrete_controller(
            F,
            g,
            K,
            Kxs,
            ki,
            dt,
            delay=delay,
            compensate=compensate_delay,
            integral=integral,
        )
        ref_advance = bool(delay and compensate_delay)
        plant_ff = 0.0 if delay else 1.0
    Ctrl = L = None
    if lti:
        Ctrl = control.ss(Ac, Bc, Cc, Dc, ts)
        L = -control.series(P, Ctrl)  # -C P (P first, then C)
    m = Ac.shape[0]
    A_cl = np.zeros((n + m, n + m))
    A_cl[:n, :n] = Ap + float(Dc[0, 0]) * np.outer(Bp, Cp)
    A_cl[:n, n:] = np.outer(Bp, Cc[0])
    A_cl[n:, :n] = np.outer(Bc[:, 0], Cp)
    A_cl[n:, n:] = Ac
    A_in = np.zeros_like(A_cl)
    A_in[:n, :n] = float(Dc[0, 0]) * np.outer(Bp, Cp)
    A_in[:n, n:] = np.outer(Bp, Cc[0])
    B_ff = np.concatenate([plant_ff * Bp, b_ff])
    B_int = np.concatenate([np.zeros(n), b_int])
    return LoopSystems(P, Ctrl, L, A_cl, B_ff, B_int, Kr, ref_advance, dt, A_in)


def _state_feedback(
    Ap: np.ndarray, Bp: np.ndarray, Kxs: np.ndarray, Kr: Any, dt: float | None, lti: bool
) -> LoopSystems:
    """The true-state-feedback comparison loop ``u = Kx[:2] x`` (scaled plant ``Ap, Bp``)."""
    ts = dt if dt else 0
    Kst = Kxs[:2]  # u = Kx[:2] x (+ a1/a3 x3: a disturbance feed-through)
    Ctrl = Pst = L = None
    if lti:
        import control

        Ctrl = control.ss([], [], [], Kst[None, :], ts)
        Pst = control.ss(Ap, Bp[:, None], np.eye(2), 0.0, ts)
        L = control.ss(Ap, Bp[:, None], -Kst[None, :], 0.0, ts)
    A_cl = Ap + np.outer(Bp, Kst)
    return LoopSystems(Pst, Ctrl, L, A_cl, Bp.copy(), np.zeros(2), Kr, False, dt, np.outer(Bp, Kst))


def _continuous_controller(
    params: BoucWenParams, l: np.ndarray, s3: np.ndarray, Kxs: np.ndarray
) -> tuple[np.ndarray, ...]:
    """``(Ac, Bc, Cc, Dc, b_ff, b_int)`` of the continuous observer and eq. (12), scaled by ``s3``.

    ``xhat' = (A0 - l C) xhat + B0 u + l y``, ``u = Kx xhat``.
    """
    A0 = np.array([[0.0, 1.0, 0.0], [-params.a1, -params.a2, -params.a1], [0.0, 0.0, 0.0]])
    B0 = s3 * np.array([0.0, params.a3, 0.0])
    A0 = s3[:, None] * A0 / s3[None, :]
    ls = s3 * l
    Ac = A0 - np.outer(ls, _C3) + np.outer(B0, Kxs)
    return Ac, ls[:, None], Kxs[None, :], np.zeros((1, 1)), B0, np.zeros(3)


def closed_loop_matrix(loop: ClosedLoop, **kw: Any) -> np.ndarray:
    """Closed-loop state matrix (see :func:`loop_systems` for the keywords)."""
    return loop_systems(loop, lti=False, **kw).A_cl


def loop_parts(
    loop: ClosedLoop, estimator: str
) -> tuple[BoucWenParams, TrackingController, float | None, bool]:
    """``(model, law, dt, delay)`` of a loop the linear analysis covers, or ``InputError``.

    The analysis covers the PHSO's linear part (the ESO's is the same with ``x3``
    held) and eq. (12) in either form; ``estimator="state"`` ignores the observer.
    """
    if not isinstance(loop, ClosedLoop):
        raise InputError(f"loop must be a ClosedLoop, got {type(loop).__name__}")
    loop.require_observer("the eq. (12) loop analysis (analyze_baseline analyses a baseline)")
    if estimator not in ("observer", "state"):
        raise InputError(f"estimator must be 'observer' or 'state', got {estimator!r}")
    if estimator == "observer" and loop.observer.kind not in ("phso", "eso"):
        raise InputError(
            "the linear loop analysis covers the PHSO and the ESO (3 gains), not "
            f"{loop.observer.kind!r}"
        )
    ctrl, dt = loop.controller, loop.dt
    if dt is None and loop.delay:
        raise InputError("the computation delay needs a sample time dt (s)")
    return loop.model, ctrl, dt, loop.delay


def stability(A: np.ndarray, dt: float | None) -> tuple[bool, float]:
    """``(stable, spectral abscissa)`` (``dt`` None) or ``(stable, spectral radius)``."""
    ev = np.linalg.eigvals(A)
    if dt is None:
        m = float(np.max(ev.real))
        return m < 0, m
    r = float(np.max(np.abs(ev)))
    return r < 1, r


def gain_interval(build, dt, *, k_hi: float = 1e4) -> tuple[float, float]:
    """Loop-gain interval around 1 for which the closed loop stays stable."""
    if not stability(build(1.0), dt)[0]:
        return (math.nan, math.nan)

    def edge(k_out: float) -> float:
        k_in = 1.0
        if stability(build(k_out), dt)[0]:
            return k_out
        for _ in range(60):
            mid = math.sqrt(k_in * k_out) if k_out > 0 else 0.5 * (k_in + k_out)
            if stability(build(mid), dt)[0]:
                k_in = mid
            else:
                k_out = mid
            if abs(k_out - k_in) <= 1e-3 * k_in:
                break
        return k_in

    # scan first so a stable island beyond an unstable stretch is not mistaken
    grid_up = np.geomspace(1.0, k_hi, 40)[1:]
    hi = k_hi
    for k in grid_up:
        if not stability(build(float(k)), dt)[0]:
            hi = edge(float(k))
            break
    grid_dn = np.geomspace(1.0, 1e-4, 40)[1:]
    lo = 0.0
    for k in grid_dn:
        if not stability(build(float(k)), dt)[0]:
            lo = edge(float(k))
            break
    return (lo, hi)
