"""The sample step of the sampled-data loop, written once for one run and for a batch.

:func:`correct` (the measurement update) and :func:`advance` (the law, the plant's
ZOH step with its exact hysteresis jump, the observer's prediction and the delay)
are plain arithmetic on the fields of a :class:`LoopState`. With Python floats they
are :func:`bwdesign.sim.simulate`'s fast path. :func:`bwdesign.sim.simulate_batch` runs
the same step compiled (:mod:`bwdesign.sim.compiled`, the same operations in the same
order, written out as scalar code). The step also runs on numpy arrays of ``N`` scenarios
(:data:`ARRAY`: clipping and :class:`BatchHysteresis` element-wise), which
:func:`hysteresis_increment_batch` and the tests use.

Per sample ``k`` (see :mod:`bwdesign.sim`)::

    correct(z_k)   posterior estimate (the PHDO's law sees x3hat + dhat)
    advance(k)     u_k from the law (or the delayed one), plant jump and ZOH step
                   (its linear part driven by u_k + d_k when the run has an input
                   disturbance), observer prediction with the applied input, next
                   delayed input

A baseline loop (:class:`~bwdesign.control.baselines.BaselineController`, no observer)
runs :func:`advance_baseline` instead: the law of
:func:`bwdesign.control.baselines.pid_step` on the measurement ``z_k`` and the
feedforward sample, then the same plant step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..control.baselines import PIDState, pid_step
from ..control.controllers import solve_jump
from ..control.loop import ClosedLoop
from ..model.params import BoucWenParams
from ..model.plant import discretize, hysteresis_increment
from ..observers.gains import discrete_gains, disturbance_discrete_gains

__all__ = [
    "LoopConstants",
    "LoopState",
    "Ops",
    "SCALAR",
    "ARRAY",
    "correct",
    "advance",
    "discrete_observer_gains",
    "hysteresis_increment_batch",
    "BatchHysteresis",
    "BaselineConstants",
    "BaselineState",
    "advance_baseline",
]


@dataclass(frozen=True)
class Ops:
    """The element-wise operations that differ between one run and a batch."""

    clip: Any  # clip(v, lo, hi)
    batch: bool


SCALAR = Ops(clip=lambda v, lo, hi: min(max(v, lo), hi), batch=False)
ARRAY = Ops(clip=lambda v, lo, hi: np.minimum(np.maximum(v, lo), hi), batch=True)


def hysteresis_increment_batch(alpha, beta, gamma, h, u0, u1):
    """:func:`bwdesign.hysteresis_increment` over arrays (parameters may be arrays too).

    The same closed form and the same float operations per element; each element
    evaluates only the branch it ends on (one ``expm1``). The rare
    special cases (``beta = gamma``, a vanishing exponent) are patched by mask, so
    the common path costs no second evaluation.
    """
    h, u0, u1 = np.broadcast_arrays(
        *(np.atleast_1d(np.asarray(v, dtype=float)) for v in (h, u0, u1))
    )
    with np.errstate(all="ignore"):
        return BatchHysteresis(alpha, beta, gamma)(np.array(h), u0, u1)


class BatchHysteresis:
    """:func:`hysteresis_increment_batch` for fixed parameters, called once per sample.

    What depends on the parameters only (``beta - gamma``, ``beta + gamma``, which
    elements have ``beta = gamma``) is computed once; a call takes arrays of one
    shape (``h`` is not modified) and runs inside the caller's
    ``np.errstate(all="ignore")``. The same float operations per element as
    :func:`bwdesign.hysteresis_increment`.
    """

    __slots__ = ("alpha", "cm", "cp", "flat")

    def __init__(self, alpha, beta, gamma):
        self.alpha = alpha
        self.cm = beta - gamma
        self.cp = beta + gamma
        flat = np.asarray(self.cm == 0.0)
        self.flat = flat if flat.any() else None

    def __call__(self, h, u0, u1):
        alpha, cm = self.alpha, self.cm
        du = u1 - u0
        s = np.copysign(1.0, du)
        g = s * h
        w = np.abs(du)
        arg = -cm * g / alpha
        wz = np.log1p(arg) / cm
        wz[~(arg > -1.0)] = np.inf
        if self.flat is not None:
            wz = np.where(self.flat, -g / alpha, wz)
        neg = g < 0.0
        first = neg & (w <= wz)
        cross = neg & ~first
        c = np.where(first, cm, self.cp)
        g[cross] = 0.0  # g = s * h is this call's own array
        w = np.where(cross, w - wz, w)
        x = c * w
        e = np.expm1(-x)
        out = g + e * (g - alpha / c)
        small = ~(np.abs(x) >= 1e-8)  # NaN too, as the scalar branch decides it
        if small.any():
            xs, es, gs = x[small], e[small], g[small]
            frac = 1.0 - xs / 2.0 + xs * xs / 6.0
            out[small] = gs + (gs * es + (alpha * w)[small] * frac)
        out = s * out
        still = du == 0.0
        out[still] = h[still]
        return out


class LoopConstants:
    """Everything fixed during a run: gains, ZOH matrices, reference terms, switches.

    The plant's matrices ``p..``/``pg.`` and its hysteresis ``plant_h`` are floats for
    one run and arrays (one per scenario) for a batch; the model's are floats.
    """

    __slots__ = (
        "K1", "K2", "K3", "K4", "four", "phso", "m11", "m12", "m13", "m21", "m22", "m23",
        "mg1", "mg2", "p11", "p12", "p13", "p21", "p22", "p23", "pg1", "pg2", "kx1", "kx2",
        "kx3", "ki", "cdt", "integral", "ulo", "uhi", "clip", "limits", "jump", "ff", "xd",
        "delay", "compensate", "plant_h", "model_h", "model", "ops", "dist",
    )  # fmt: skip

    def __init__(self, loop: ClosedLoop, K: Any, ref: tuple[Any, Any, Any], ops: Ops):
        ctrl = loop.controller
        xd_all, vd_all, ad_all = ref
        Kx, Kr = ctrl.linear_gains()
        self.ff = (Kr[0] * xd_all + Kr[1] * vd_all + Kr[2] * ad_all).tolist()
        self.xd = np.asarray(xd_all, dtype=float).tolist()
        self.kx1, self.kx2, self.kx3 = (float(v) for v in Kx)
        self.integral = ctrl.integral_rate is not None
        self.ki = float(ctrl.ki)
        self.cdt = float(getattr(ctrl, "dt", loop.dt))
        self.ulo, self.uhi = ctrl.u_limits if ctrl.u_limits else (-math.inf, math.inf)
        self.clip = bool(ctrl.estimate_limits)
        self.limits = ctrl.estimate_limits
        self.jump = bool(ctrl.hysteresis_jump)
        self.four = loop.observer.four_state
        self.phso = loop.observer.hysteresis_model
        self.K1, self.K2, self.K3 = (float(v) for v in K[:3])
        self.K4 = float(K[3]) if self.four else 0.0
        zm = discretize(loop.model, loop.dt)
        (self.m11, self.m12, self.m13), (self.m21, self.m22, self.m23) = zm.F[0], zm.F[1]
        self.mg1, self.mg2 = float(zm.g[0]), float(zm.g[1])
        self.delay, self.compensate = loop.delay, loop.compensate_delay
        self.model = loop.model
        self.ops = ops
        #: the plant's input disturbance per sample (held over it), or None:
        #: a list of floats for one run, an (n, N) array for a batch
        self.dist: Any = None
        m = loop.model
        if ops.batch:
            self.model_h = BatchHysteresis(m.alpha, m.beta, m.gamma)
        else:
            self.model_h = lambda h, u0, u1: hysteresis_increment(m, h, u0, u1)

    def set_plant(self, tp: BoucWenParams, dt: float) -> None:
        """One true plant (one run): its exact ZOH matrices (the batch's too,
        :func:`.zoh.true_matrices`) and hysteresis."""
        zt = discretize(tp, dt)
        (self.p11, self.p12, self.p13), (self.p21, self.p22, self.p23) = zt.F[0], zt.F[1]
        self.pg1, self.pg2 = float(zt.g[0]), float(zt.g[1])
        self.plant_h = lambda h, u0, u1: hysteresis_increment(tp, h, u0, u1)

    def set_plants(self, T: dict[str, np.ndarray]) -> None:
        """A batch of true plants: arrays of their ZOH entries and hysteresis parameters."""
        for name in ("p11", "p12", "p13", "p21", "p22", "p23"):
            setattr(self, name, T[name])
        self.pg1, self.pg2 = T["g1"], T["g2"]
        self.plant_h = BatchHysteresis(T["alpha"], T["beta"], T["gamma"])


class LoopState:
    """Plant state, estimate, held and delayed inputs and the law's integrator."""

    __slots__ = ("x1", "x2", "x3", "h1", "h2", "h3", "hd", "hw", "up", "ua", "q")

    def __init__(self, x0: Any, xhat0: Any, hd: Any, u_prev: Any, q: Any):
        self.x1, self.x2, self.x3 = x0
        self.h1, self.h2, self.h3 = xhat0
        self.hd = hd
        self.hw = self.h3  # set by correct() before the law reads it
        self.up = u_prev
        self.ua = u_prev
        self.q = q


def discrete_observer_gains(loop: ClosedLoop) -> np.ndarray:
    """The sampled observer's gain ``K`` (pole-matched to the continuous gains)."""
    if loop.observer.four_state:
        return disturbance_discrete_gains(loop.model, loop.observer.gains, loop.dt)
    return discrete_gains(loop.model, loop.observer.gains, loop.dt)


def correct(c: LoopConstants, s: LoopState, zk: Any) -> None:
    """The measurement update with ``z_k``; sets the lumped estimate ``s.hw`` the law sees."""
    r = zk - s.h1
    s.h1 = s.h1 + c.K1 * r
    s.h2 = s.h2 + c.K2 * r
    s.h3 = s.h3 + c.K3 * r
    if c.four:
        s.hd = s.hd + c.K4 * r
        s.hw = s.h3 + s.hd
    else:
        s.hw = s.h3


def _law(c: LoopConstants, s: LoopState, a: Any, b: Any, h: Any, i: int, uprev: Any) -> Any:
    if c.clip:
        (c1l, c1h), (c2l, c2h), (c3l, c3h) = c.limits
        clip = c.ops.clip
        a, b, h = clip(a, c1l, c1h), clip(b, c2l, c2h), clip(h, c3l, c3h)
    f = c.ff[i] + c.ki * s.q
    if c.jump:
        v = solve_jump(c.model, f + c.kx1 * a + c.kx2 * b, c.kx3, h, uprev)
    else:
        v = f + c.kx1 * a + c.kx2 * b + c.kx3 * h
    if c.integral:
        s.q = s.q + c.cdt * (a - c.xd[i])
    return c.ops.clip(v, c.ulo, c.uhi)


def advance(c: LoopConstants, s: LoopState, k: int) -> tuple[Any, Any]:
    """Sample ``k`` after :func:`correct`: returns the applied input and the one before it."""
    if not c.delay:
        applied = _law(c, s, s.h1, s.h2, s.hw, k, s.up)
    else:
        applied = s.ua
        if not c.compensate:
            u_next = _law(c, s, s.h1, s.h2, s.hw, k, s.ua)
    up = s.up
    x1, x2 = s.x1, s.x2
    hh = c.plant_h(s.x3, up, applied)
    # the plant's linear part sees u + d (d held over the sample); its hysteresis sees u
    ud = applied if c.dist is None else applied + c.dist[k]
    s.x1 = c.p11 * x1 + c.p12 * x2 + c.p13 * hh + c.pg1 * ud
    s.x2 = c.p21 * x1 + c.p22 * x2 + c.p23 * hh + c.pg2 * ud
    s.x3 = hh
    h1, h2, hd = s.h1, s.h2, s.hd
    g3 = c.model_h(s.h3, up, applied) if c.phso else s.h3
    gw = g3 + hd if c.four else g3
    s.h1 = c.m11 * h1 + c.m12 * h2 + c.m13 * gw + c.mg1 * applied
    s.h2 = c.m21 * h1 + c.m22 * h2 + c.m23 * gw + c.mg2 * applied
    s.h3 = g3
    s.hw = g3 + hd if c.four else g3
    if c.delay:
        if c.compensate:
            u_next = _law(c, s, s.h1, s.h2, s.hw, k + 1, applied)
        s.ua = u_next
    s.up = applied
    return applied, up


class BaselineConstants(LoopConstants):
    """What a baseline run keeps fixed: the law's numbers, the feedforward and reference
    samples, the plant (:meth:`set_plant`, :meth:`set_plants` as for the observer loop).

    ``ff[k]`` is the feedforward for the input applied after sample ``k``'s law (at
    ``t_k + dt/2``, or ``t_{k+1} + dt/2`` with a computation delay).
    """

    __slots__ = ("law",)

    def __init__(self, loop: ClosedLoop, ff: Any, ref: tuple[Any, Any, Any], ops: Ops):
        self.law = loop.controller.constants()
        self.ff = np.asarray(ff, dtype=float).tolist()
        self.xd = np.asarray(ref[0], dtype=float).tolist()
        self.delay = loop.delay
        self.ops = ops
        self.dist: Any = None


class BaselineState:
    """Plant state, held and delayed inputs, and the controller's :class:`PIDState`."""

    __slots__ = ("x1", "x2", "x3", "up", "ua", "pid")

    def __init__(self, x0: Any, u_prev: Any, pid: PIDState):
        self.x1, self.x2, self.x3 = x0
        self.up = u_prev
        self.ua = u_prev
        self.pid = pid


def advance_baseline(c: BaselineConstants, s: BaselineState, k: int, zk: Any) -> tuple[Any, Any]:
    """Sample ``k`` of a baseline loop: the law on ``z_k``, then the plant's step (the same
    jump and ZOH step as :func:`advance`). Returns the applied input and the one before."""
    u = pid_step(c.law, s.pid, zk, c.xd[k], c.ff[k], c.ops.clip)
    if c.delay:
        applied, s.ua = s.ua, u
    else:
        applied = u
    up = s.up
    x1, x2 = s.x1, s.x2
    hh = c.plant_h(s.x3, up, applied)
    ud = applied if c.dist is None else applied + c.dist[k]
    s.x1 = c.p11 * x1 + c.p12 * x2 + c.p13 * hh + c.pg1 * ud
    s.x2 = c.p21 * x1 + c.p22 * x2 + c.p23 * hh + c.pg2 * ud
    s.x3 = hh
    s.up = applied
    return applied, up
