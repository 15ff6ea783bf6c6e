"""The Bouc-Wen plant: continuous right-hand side and exact sampled-data model.

Sampled-data model (docs/design.md, section "Exact sampling"). With the input held over each sample
(zero-order hold), the model is discretised *exactly*:

1. At ``t_k`` the held input jumps from ``u_{k-1}`` to ``u_k``. Bouc-Wen is
   rate independent, so along the jump the hysteresis state follows
   ``dh/du = alpha - beta s h - gamma |h|`` (``s`` the sign of the jump), a
   piecewise-linear ODE in ``u`` solved in closed form by
   :func:`hysteresis_increment`.
2. Over ``[t_k, t_{k+1})`` both ``u`` and ``x3`` are constant and ``(x1, x2)``
   follow a linear ODE, propagated with a matrix exponential.

One step is therefore ``x_{k+1} = F [x1, x2, h_k+] + g u_k`` with the 3x3
matrix ``F`` and vector ``g`` of :func:`discretize`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from ..errors import InputError
from ..validate import DT, NONNEGATIVE, POSITIVE, real
from .params import BoucWenParams, require_bounded

__all__ = [
    "ZOHModel",
    "discretize",
    "phi",
    "rhs",
    "hysteresis_increment",
    "hysteresis_slope_range",
    "hysteresis_jump_bound",
    "hysteresis_jump_change_bound",
    "zoh_step",
    "simulate_zoh",
    "check_sample_time",
    "slowest_decay",
]


def phi(params: BoucWenParams, udot: float, x3: float) -> float:
    """Hysteresis rate ``alpha u' - beta |u'| x3 - gamma u' |x3|`` (length unit/s)."""
    return params.alpha * udot - params.beta * abs(udot) * x3 - params.gamma * udot * abs(x3)


def rhs(params: BoucWenParams, x: np.ndarray, u: float, udot: float) -> np.ndarray:
    """Continuous-time right-hand side of paper eq. (2) for a smooth input.

    Parameters
    ----------
    params : BoucWenParams
    x : array_like, shape (3,)
        State (x1 displacement, x2 velocity, x3 hysteresis).
    u : float
        Input (V).
    udot : float
        Input rate u' (V/s).

    Returns
    -------
    ndarray, shape (3,)
    """
    x1, x2, x3 = x
    return np.array(
        [
            x2,
            -params.a1 * x1 - params.a2 * x2 - params.a1 * x3 + params.a3 * u,
            phi(params, udot, x3),
        ]
    )


def _branch(h: float, w: float, alpha: float, c: float) -> float:
    """Solve ``dh/dw = alpha - c h`` from ``h`` over a length ``w >= 0`` in closed form."""
    x = c * w
    try:
        e = math.expm1(-x)  # e^{-x} - 1: one libm call gives the decay and the gain
    except OverflowError:  # only for unbounded models (c < 0)
        return math.copysign(math.inf, h if h != 0 else alpha)
    if not abs(x) >= 1e-8:  # NaN too: alpha / c below only where c != 0
        frac = 1.0 - x / 2.0 + x * x / 6.0  # (1 - e^{-x})/x
        return h + (h * e + alpha * w * frac)
    # h e^{-x} + (alpha / c) (1 - e^{-x}) = h + (h - alpha / c) (e^{-x} - 1): no second
    # call (exp) and no division by x; alpha / c is the branch's fixed point, the same
    # float wherever it is computed (the compiled loop and the C export fold it once)
    return h + e * (h - alpha / c)


def hysteresis_increment(params: BoucWenParams, h: float, u0: float, u1: float) -> float:
    """Hysteresis state after the input moves from ``u0`` to ``u1``, in closed form.

    Bouc-Wen is rate independent, so the result depends only on the path of
    ``u``, not on its speed. Along a monotone path with direction
    ``s = sign(u1 - u0)`` the state obeys ``dh/du = alpha - beta s h - gamma |h|``.
    In the frame ``g = s h``, ``w = |u - u0|`` this is ``dg/dw = alpha - c g``
    with ``c = beta + gamma`` for ``g >= 0`` and ``c = beta - gamma`` for
    ``g < 0``: two linear branches. Starting with ``g < 0`` the state may cross
    zero inside the jump (at a distance found in closed form) and continue on
    the other branch. ``u1 == u0`` returns ``h`` unchanged.

    Parameters
    ----------
    params : BoucWenParams
    h : float
        Hysteresis state before the jump (length unit).
    u0, u1 : float
        Input before and after the jump (V).

    Returns
    -------
    float
        Hysteresis state after the jump.

    Examples
    --------
    >>> from bwdesign.model.params import preset
    >>> p = preset("paper_experiment")
    >>> h = hysteresis_increment(p, 0.0, 0.0, 100.0)   # saturates at alpha/(beta+gamma)
    >>> abs(h - p.alpha / (p.beta + p.gamma)) < 1e-9
    True
    """
    du = u1 - u0
    if du == 0.0:
        return float(h)
    s = 1.0 if du > 0.0 else -1.0
    g = s * h
    w = abs(du)
    alpha = params.alpha
    if g < 0.0:
        cm = params.beta - params.gamma
        if cm == 0.0:
            wz = -g / alpha
        else:
            arg = -cm * g / alpha
            # Ends before the zero crossing, decided without log1p where it is clear:
            # log1p(a) lies between a/(1 + a) and a, so the crossing log1p(arg)/cm is at
            # least b/|cm| with b = arg/(1 + arg) (cm > 0) or -arg (cm < 0); where
            # w |cm| <= b/2 the exact test below holds by a factor of two, which no
            # rounding of either side reverses: the same branch and numbers. Tested as
            # num / den with both sides multiplied by den > 0 (no division); b >= 1e-6
            # keeps an underflow of w |cm| from deciding; NaN falls through.
            num, den = (arg, 1.0 + arg) if cm > 0.0 else (-arg, 1.0)
            if num >= 1e-6 * den and w * abs(cm) * den <= 0.5 * num:
                return s * _branch(g, w, alpha, cm)
            wz = math.log1p(arg) / cm if arg > -1.0 else math.inf
        if w <= wz:
            return s * _branch(g, w, alpha, cm)
        g, w = 0.0, w - wz
    return s * _branch(g, w, alpha, params.beta + params.gamma)


def hysteresis_slope_range(params: BoucWenParams) -> tuple[float, float]:
    """The range of ``dx3/du`` along any input path: ``|x3(u1) - x3(u0)| <= hi |u1 - u0|``.

    Along a monotone path of direction ``s``, ``g = s x3`` obeys ``dg/dw = alpha - c g``
    (``w = |u - u0|``) with ``c = beta + gamma`` for ``g >= 0`` and ``beta - gamma`` for
    ``g < 0`` (:func:`hysteresis_increment`). In the bounded class (``alpha > 0``,
    ``beta + gamma > 0``, ``beta - gamma >= 0``) with ``|x3| <= h_max = alpha / (beta +
    gamma)`` that is in ``[0, alpha]`` for ``g >= 0`` and in ``[alpha, alpha + (beta -
    gamma) h_max]`` for ``g < 0``: the range is ``(0, alpha + (beta - gamma) h_max)``,
    ``hi = 2 alpha beta / (beta + gamma)``. Outside the bounded class (no ``h_max``):
    ``(alpha, alpha)``, the slope at ``x3 = 0``.

    Examples
    --------
    >>> from bwdesign.model.params import preset
    >>> p = preset("paper_experiment")
    >>> lo, hi = hysteresis_slope_range(p)
    >>> lo, abs(hi - 2 * p.alpha * p.beta / (p.beta + p.gamma)) < 1e-12
    (0.0, True)
    """
    bc = params.bounded_class()
    if not bc.bounded:
        return (params.alpha, params.alpha)
    return (0.0, params.alpha + (params.beta - params.gamma) * bc.h_max)


#: Grid of the input step in :func:`hysteresis_jump_bound` (its bound is within ``hi step /
#: JUMP_GRID`` of the supremum it bounds).
JUMP_GRID = 4096


def hysteresis_jump_bound(
    plants: list[BoucWenParams], step: float, second: float | None = None
) -> float:
    """Bound of one sample's hysteresis jump ``|x3_{k+1} - x3_k|`` of any plant in ``plants``.

    The input's steps are bounded, ``|u_{k+1} - u_k| <= step``; with ``second``, so are
    its second differences, ``|u_{k+1} - 2 u_k + u_{k-1}| <= second``. Without
    ``second`` the bound is ``hi step`` (:func:`hysteresis_slope_range`, the largest
    over ``plants``). With it, the slope is high only just after a reversal, where the
    step is small:

    - along a monotone path the slope ``psi = dx3/du`` of a bounded plant obeys
      ``dpsi/dw = -c psi`` (``w`` the path length) with ``c = beta - gamma`` while
      ``s x3 < 0`` and ``c = beta + gamma`` once ``s x3 >= 0``, where ``psi <= alpha``
      (:func:`hysteresis_increment`'s two branches: ``psi = alpha - c g``); so from any
      state ``psi(w) <= Psi(w)``, the solution from ``hi`` that decays at ``cA = min(beta
      - gamma, beta + gamma)`` above ``alpha`` and at ``cB = beta + gamma`` below (each
      constant the least, ``hi`` the largest and ``alpha`` the least over ``plants``: the
      decay is slower, so ``Psi`` stays above every plant's slope);
    - a step of size ``v`` in direction ``s`` ends a run of steps in that direction that
      began after a step of the other sign or zero, so the path travelled in the run
      before it is at least ``w_min(v) = sum_{m >= 1} max(0, v - m second)``;
    - so the jump is at most ``int_{w_min(v)}^{w_min(v) + v} Psi``, maximised over ``0 <
      v <= step`` on a grid of :data:`JUMP_GRID` intervals, each bounded from above
      (``Psi`` decreases: the interval's smallest ``w_min`` and largest ``v``).

    Never above ``hi step``. Plants outside the bounded class, or no ``second``: ``hi
    step``.

    Examples
    --------
    >>> from bwdesign.model.params import preset
    >>> p = preset("paper_experiment")
    >>> hi = hysteresis_slope_range(p)[1]
    >>> hysteresis_jump_bound([p], 0.08) == hi * 0.08
    True
    >>> hysteresis_jump_bound([p], 0.08, 2.5e-4) < 0.3 * hi * 0.08
    True
    """
    step = real(step, "step", within=NONNEGATIVE)
    plants = list(plants)
    if not plants:
        raise InputError("hysteresis_jump_bound needs at least one plant")
    hi = max(hysteresis_slope_range(p)[1] for p in plants)
    flat = hi * step
    if second is None or not all(p.bounded_class().bounded for p in plants) or step == 0:
        return flat
    second = real(second, "second", within=POSITIVE)
    _, _, area, _ = _turns(plants, step, second)
    return float(min(flat, float(np.max(area))))


def _turns(
    plants: list[BoucWenParams], step: float, second: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, _Slope]:
    """:func:`hysteresis_jump_bound`'s grid: the steps ``v`` (``JUMP_GRID + 1`` points from
    0 to ``step``), the least travel ``w_min`` before a step in each interval (at its
    left end), the bound of the jump over each interval (rounding added) and ``Psi``."""
    hi = max(hysteresis_slope_range(p)[1] for p in plants)
    slope = _Slope(
        hi,
        min(p.alpha for p in plants),
        min(min(p.beta - p.gamma, p.beta + p.gamma) for p in plants),
        min(p.beta + p.gamma for p in plants),
    )
    v = np.linspace(0.0, step, JUMP_GRID + 1)
    m = np.maximum(np.ceil(v[:-1] / second) - 1.0, 0.0)  # positive terms of w_min
    w0 = np.maximum(m * v[:-1] - second * m * (m + 1) / 2, 0.0) * (1 - 1e-12)
    area = slope.area(w0 + v[1:]) - slope.area(w0)
    # the two areas are below hi w + 2 alpha / cb; their rounding is added
    area += 8 * np.finfo(float).eps * (hi * step + 2 * hi * float(w0.max()))
    return v, w0, area, slope


def hysteresis_jump_change_bound(
    plants: list[BoucWenParams], step: float, second: float, jump: float
) -> float:
    """Bound of the change ``|j_{k+1} - j_k|`` of one sample's hysteresis jump from one
    sample to the next, for any plant in ``plants`` (bounded class), once the input has
    turned (as :func:`hysteresis_jump_bound`, whose ``second`` it shares).

    ``j_k = F(x3_k, du_k)`` with ``F(h, v) = H(h, v) - h`` (:func:`hysteresis_increment`)
    and ``x3_{k+1} = x3_k + j_k``, so ``j_{k+1} - j_k = [F(x3_{k+1}, du_{k+1}) -
    F(x3_{k+1}, du_k)] + [F(x3_{k+1}, du_k) - F(x3_k, du_k)]``:

    - the second part: ``H`` moves with its start by a factor in ``[exp(-c |v|), 1]``
      (``c = max(beta + gamma, beta - gamma)``, the decay of the state's sensitivity
      along the path), so it is at most ``(1 - exp(-c |du_k|)) |j_k|``, and ``|j_k|`` is
      at most the jump bound at that very step;
    - the first part is the slope beyond ``du_k`` times ``|du_{k+1} - du_k| <= second``:
      the path goes on from where step ``k`` left it, so that slope is at most
      ``Psi(w_min(v) + v)`` (``v = |du_k|``); where ``v <= second`` the input may turn
      and it is ``hi`` (the slope in ``u`` is in ``[0, hi]`` either side of 0).

    The larger of the two summed, over the same grid as the jump bound, each interval
    bounded from above; never above ``hi second + (1 - exp(-c step)) jump`` (``jump``:
    :func:`hysteresis_jump_bound` over ``step``) nor ``2 jump``.
    """
    step = real(step, "step", within=NONNEGATIVE)
    second = real(second, "second", within=POSITIVE)
    jump = real(jump, "jump", within=NONNEGATIVE)
    plants = list(plants)
    if not plants or not all(p.bounded_class().bounded for p in plants):
        raise InputError("hysteresis_jump_change_bound needs bounded plants")
    if step == 0:
        return 0.0
    v, w0, area, slope = _turns(plants, step, second)
    c = max(max(p.beta + p.gamma, p.beta - p.gamma) for p in plants)
    total = (slope.hi * second + -math.expm1(-c * step) * jump) * (1 + 8 * np.finfo(float).eps)
    beyond = np.where(v[:-1] < second, slope.hi, slope.at(w0 + v[:-1]))
    joint = second * beyond + -np.expm1(-c * v[1:]) * np.minimum(area, jump)
    joint = float(np.max(joint)) * (1 + 8 * np.finfo(float).eps)
    return float(min(2 * jump, total, joint))


@dataclass(frozen=True)
class _Slope:
    """``Psi`` of :func:`hysteresis_jump_bound`: from ``hi``, decaying at ``ca`` above
    ``alpha`` and at ``cb`` below, along the path length ``w``."""

    hi: float
    alpha: float
    ca: float
    cb: float

    @property
    def knee(self) -> float:
        """Where ``Psi`` reaches ``alpha`` (0: at once; inf: never)."""
        if self.hi <= self.alpha:
            return 0.0
        return math.log(self.hi / self.alpha) / self.ca if self.ca > 0 else math.inf

    def at(self, w: np.ndarray) -> np.ndarray:
        """``Psi(w)``."""
        hi, alpha, ca, cb, knee = self.hi, self.alpha, self.ca, self.cb, self.knee
        if knee == 0.0:  # decays at cb from the start
            return hi * np.exp(-cb * w)
        if knee == math.inf:  # never falls to alpha
            return np.full_like(w, hi)
        return np.where(w < knee, hi * np.exp(-ca * w), alpha * np.exp(-cb * (w - knee)))

    def area(self, w: np.ndarray) -> np.ndarray:
        """``int_0^w Psi``."""
        hi, alpha, ca, cb, knee = self.hi, self.alpha, self.ca, self.cb, self.knee
        if knee == 0.0:
            return hi * -np.expm1(-cb * w) / cb
        if knee == math.inf:
            return hi * w
        first = hi * -np.expm1(-ca * np.minimum(w, knee)) / ca
        return first + alpha * -np.expm1(-cb * np.maximum(w - knee, 0.0)) / cb


@dataclass(frozen=True)
class ZOHModel:
    """Exact zero-order-hold discretisation of the linear part at sample time ``dt``.

    ``x_{k+1} = F @ [x1_k, x2_k, h_k+] + g * u_k`` where ``h_k+`` is the
    hysteresis state after the jump at ``t_k``.

    Attributes
    ----------
    F : ndarray, shape (3, 3)
        ``[[Phi, -a1 Gamma], [0, 0, 1]]`` with ``Phi = expm(Ac dt)`` and
        ``Gamma = int_0^dt expm(Ac s) ds e2``.
    g : ndarray, shape (3,)
        ``[a3 Gamma, 0]``.
    dt : float
        Sample time (s).
    """

    F: np.ndarray
    g: np.ndarray
    dt: float


@functools.lru_cache(maxsize=128)
def discretize(params: BoucWenParams, dt: float) -> ZOHModel:
    """Exact ZOH matrices of the linear part (cached per parameter set and ``dt``).

    Parameters
    ----------
    params : BoucWenParams
    dt : float
        Sample time (s), see :func:`check_sample_time`.
    """
    dt = check_sample_time(params, dt)
    E = zoh_exponentials(np.array([params.a1]), np.array([params.a2]), np.array([params.a3]), dt)[0]
    F = E[:3, :3].copy()
    g = E[:3, 3].copy()
    F[2] = (0.0, 0.0, 1.0)
    g[2] = 0.0
    F.setflags(write=False)
    g.setflags(write=False)
    return ZOHModel(F=F, g=g, dt=dt)


def zoh_exponentials(a1: np.ndarray, a2: np.ndarray, a3: np.ndarray, dt: float) -> np.ndarray:
    """The exact ZOH exponentials of many linear parts at once, shape ``(N, 4, 4)``.

    Row ``i`` is ``expm`` of the augmented matrix of ``d/dt [x1, x2, x3, u]`` (``x3`` and
    ``u`` constant) of the plant ``(a1[i], a2[i], a3[i])``, balanced by ``D = diag(1, w0,
    1, a1/a3)``, ``w0 = sqrt(a1)``, so every entry is ``O(w0)`` (``a1`` ranges over
    1e3..1e9 and would otherwise dominate the scaling), and scaled back. One stacked
    ``expm`` (scipy's is per matrix, so each row equals the single plant's to the bit):
    :func:`discretize` takes its matrices from here, and so does a batch of true plants
    (:func:`bwdesign.sim.zoh.true_matrices`), so both step the same numbers. ``dt`` is
    not checked here (:func:`check_sample_time`).
    """
    a1, a2, a3 = (np.asarray(x, dtype=float) for x in (a1, a2, a3))
    w0 = np.sqrt(a1)
    D = np.stack([np.ones_like(a1), w0, np.ones_like(a1), a1 / a3], axis=1)
    Mz = np.zeros((a1.size, 4, 4))
    Mz[:, 0, 1] = w0
    Mz[:, 1, 0] = -w0
    Mz[:, 1, 1] = -a2
    Mz[:, 1, 2] = -w0
    Mz[:, 1, 3] = w0
    return D[:, :, None] * expm(Mz * dt) / D[:, None, :]


def check_dt(dt: float) -> float:
    """``dt`` (s) as a float in the supported range :data:`bwdesign.validate.DT`."""
    return real(dt, "dt (s)", within=DT)


def slowest_decay(params: BoucWenParams) -> float:
    """Decay rate of the slowest mode of ``s^2 + a2 s + a1`` (1/s): ``min(-Re s)``."""
    a1, a2 = params.a1, params.a2
    disc = a2 * a2 - 4.0 * a1
    if disc <= 0:
        return 0.5 * a2
    return 2.0 * a1 / (a2 + math.sqrt(disc))  # (a2 - sqrt(disc))/2 without cancellation


#: Largest supported ``slowest_decay(params) * dt``. Over one sample every mode of
#: the plant then shrinks by at least ``exp(-20) = 2e-9``, not to rounding noise,
#: so the sampled model keeps the velocity observable from the displacement;
#: beyond it pole matching and the sampled certificates lose the information
#: (the paper_experiment stage failed at 71, with a nan in the sampled tier).
MAX_DECAY_DT = 20.0


def check_sample_time(params: BoucWenParams, dt: float) -> float:
    """``dt`` (s) checked against the supported range and against the plant.

    Supported: ``dt`` in :data:`bwdesign.validate.DT` and
    ``slowest_decay(params) * dt <= MAX_DECAY_DT`` (20).

    Raises
    ------
    InputError
        ``dt`` is not a number, not finite, or outside either range.
    """
    dt = check_dt(dt)
    sigma = slowest_decay(params)
    if sigma * dt > MAX_DECAY_DT:
        label = params.name or "the plant"
        raise InputError(
            f"dt = {dt:g} s is too long for {label}: its slowest mode decays at {sigma:.6g} 1/s "
            f"and the supported range is decay * dt <= {MAX_DECAY_DT:g}, i.e. "
            f"dt <= {MAX_DECAY_DT / sigma:.4g} s"
        )
    return dt


def _as_state(x: np.ndarray, name: str = "x") -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.shape != (3,):
        raise InputError(f"{name} must have shape (3,) (x1, x2, x3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InputError(f"{name} must be finite, got {x}")
    return x


def zoh_step(
    params: BoucWenParams, x: np.ndarray, u_prev: float, u: float, dt: float
) -> np.ndarray:
    """One exact sample of the plant.

    The hysteresis follows the jump ``u_prev -> u`` at ``t_k``; then ``u`` is held
    over ``[t_k, t_k + dt)``.

    Parameters
    ----------
    params : BoucWenParams
    x : array_like, shape (3,)
        State at ``t_k`` before the jump.
    u_prev, u : float
        Held input over the previous and the current sample (V).
    dt : float
        Sample time (s).

    Returns
    -------
    ndarray, shape (3,)
        State at ``t_{k+1}``.
    """
    x = _as_state(x)
    zoh = discretize(params, dt)
    h = hysteresis_increment(params, float(x[2]), float(u_prev), float(u))
    return zoh.F @ np.array([x[0], x[1], h]) + zoh.g * float(u)


def simulate_zoh(
    params: BoucWenParams,
    u: np.ndarray,
    dt: float,
    x0: np.ndarray,
    u_prev: float = 0.0,
    *,
    allow_unbounded: bool = False,
) -> np.ndarray:
    """Simulate the exact sampled-data plant for a held input sequence.

    Parameters
    ----------
    params : BoucWenParams
    u : array_like, shape (N,)
        Input held over each sample (V).
    dt : float
        Sample time (s).
    x0 : array_like, shape (3,)
        State at ``t_0`` (before the jump from ``u_prev`` to ``u[0]``).
    u_prev : float
        Input held before ``t_0`` (V).
    allow_unbounded : bool
        Accept parameters outside the bounded class.

    Returns
    -------
    ndarray, shape (N + 1, 3)
        Row 0 is ``x0`` as given; row ``k + 1`` is the state at ``t_{k+1}``.

    Raises
    ------
    UnboundedModelError
        The model is outside the bounded class and ``allow_unbounded`` is False.
    InputError
        ``u`` is not 1-D and finite, ``x0`` not a finite (3,) vector, ``dt <= 0``.
    """
    require_bounded(params, allow_unbounded)
    u = np.asarray(u, dtype=float)
    if u.ndim != 1:
        raise InputError(f"u must be a 1-D sequence of held inputs, got shape {u.shape}")
    if not np.all(np.isfinite(u)):
        raise InputError("u must be finite")
    u_prev = real(u_prev, "u_prev")
    x0 = _as_state(x0, "x0")
    zoh = discretize(params, dt)
    (f11, f12, f13), (f21, f22, f23) = zoh.F[0], zoh.F[1]
    g1, g2 = zoh.g[0], zoh.g[1]
    out = np.empty((u.size + 1, 3))
    out[0] = x0
    x1, x2, h = (float(v) for v in x0)
    up = float(u_prev)
    for k, uk in enumerate(u.tolist()):
        h = hysteresis_increment(params, h, up, uk)
        x1, x2 = (
            f11 * x1 + f12 * x2 + f13 * h + g1 * uk,
            f21 * x1 + f22 * x2 + f23 * h + g2 * uk,
        )
        out[k + 1] = (x1, x2, h)
        up = uk
    return out
