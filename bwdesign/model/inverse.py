"""The exact inverse of the Bouc–Wen model, sample by sample, in operations C repeats.

The input ``u`` under which ``x1`` follows ``x_d`` exactly on the model satisfies, at
each sample (rate independence: only the path of ``u`` matters),

    a3 v - a1 H(h_k, u_k, v) = R_k,    R = x_d'' + a2 x_d' + a1 x_d,

with ``H`` the closed-form hysteresis increment
(:func:`bwdesign.model.plant.hysteresis_increment`), ``u_k``, ``h_k`` the previous
input and hysteresis state. :func:`inverse_step` solves it by a safeguarded Newton
iteration whose every floating-point operation is written once more, in the same
order, by the C export of the ``pi-bwff`` baseline (:mod:`bwdesign.codegen.baselines`),
so float64 C reproduces it bit for bit (scalar ``math.expm1``/``log1p``, the
libm the C links).

The iteration, on ``F(v) = sg (a3 v - a1 H(v) - R)`` with ``sg = sign(a3)``:

1. bracket ``[lo, hi]`` from ``(R -+ a1 B)/a3``, ``B = 1.0001 max(|h_k|, h_max) + 1e-12``
   (in the bounded class ``|H| <= B``, so ``F(lo) <= 0 <= F(hi)``);
2. start at the linear predictor ``u_k + (u_k - u_{k-1})``, clipped into the bracket;
3. evaluate ``H(v)`` and ``F(v)``; ``F = 0`` ends; the sign of ``F`` moves ``lo`` or ``hi``
   to ``v``; the slope ``F'(v) = sg (a3 - a1 (alpha - beta s H - gamma |H|))`` with ``s``
   the direction of ``v - u_k`` (at ``v = u_k`` the way ``F`` says to go);
4. if ``F' > 0`` and ``|F| <= TOL (1 + |v|) F'`` (the Newton step is below ``TOL``
   relative), ``v`` and ``H(v)`` are the answer; else the Newton step if ``F' > 0`` and it
   lands strictly inside ``(lo, hi)``, otherwise the midpoint ``lo + (hi - lo)/2``;
5. at most :data:`MAX_ITER` evaluations (:class:`~bwdesign.errors.SolverError` in
   Python; the C returns its last evaluated ``v``).

The stopping test is a comparison of the same floats in both languages, so the C takes
the same iterations. ``TOL = 1e-13``: the returned ``v`` lies within about
``1e-13 (1 + |v|)`` of the root; the residual is at rounding level times ``F'/a3``.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError, SolverError
from .params import BoucWenParams, require_bounded
from .plant import hysteresis_increment
from .references import Reference

__all__ = ["MAX_ITER", "TOL", "inverse_bound", "inverse_input", "inverse_step"]

#: Relative Newton step below which the iteration stops (float64).
TOL = 1e-14
#: Most evaluations of the residual per sample.
MAX_ITER = 100


def inverse_bound(params: BoucWenParams) -> float:
    """``h_max`` of the bounded class (0 outside it): the bracket's hysteresis bound."""
    verdict = params.bounded_class()
    return verdict.h_max if verdict.bounded else 0.0


def inverse_step(
    params: BoucWenParams,
    h: float,
    u: float,
    r: float,
    guess: float,
    h_cap: float,
    tol: float = TOL,
) -> tuple[float, float]:
    """The input ``v`` solving ``a3 v - a1 H(h, u, v) = r`` and ``H(h, u, v)`` (module docstring).

    ``h``, ``u``: the hysteresis state and the input before the jump; ``guess``: the
    starting point; ``h_cap``: :func:`inverse_bound`.

    Raises
    ------
    InputError
        No root in the bracket (only outside the bounded class).
    SolverError
        :data:`MAX_ITER` evaluations without convergence.
    """
    a1, a3 = params.a1, params.a3
    alpha, beta, gamma = params.alpha, params.beta, params.gamma
    sg = 1.0 if a3 > 0.0 else -1.0
    b = 1.0001 * max(abs(h), h_cap) + 1e-12
    lo = (r - a1 * b) / a3
    hi = (r + a1 * b) / a3
    if lo > hi:
        lo, hi = hi, lo
    if h_cap == 0.0:  # outside the bounded class the bracket is not guaranteed: check it
        f_lo = sg * (a3 * lo - a1 * hysteresis_increment(params, h, u, lo) - r)
        f_hi = sg * (a3 * hi - a1 * hysteresis_increment(params, h, u, hi) - r)
        if f_lo > 0.0 or f_hi < 0.0:
            raise InputError(
                f"the exact inverse model has no input within the hysteresis bound {b:.6g} "
                "(this parameter set is outside the bounded class); state the envelope "
                "directly ([envelope] udot_max)"
            )
    v = min(max(guess, lo), hi)
    for _ in range(MAX_ITER):
        hv = hysteresis_increment(params, h, u, v)
        f = sg * (a3 * v - a1 * hv - r)
        if f == 0.0:
            return v, hv
        if f < 0.0:
            lo = v
        else:
            hi = v
        s = 1.0 if v > u or (v == u and f < 0.0) else -1.0
        d = sg * (a3 - a1 * (alpha - beta * s * hv - gamma * abs(hv)))
        vn = lo + 0.5 * (hi - lo)
        if d > 0.0:
            if abs(f) <= tol * (1.0 + abs(v)) * d:
                return v, hv
            newton = v - f / d
            if lo < newton < hi:
                vn = newton
        v = vn
    raise SolverError(
        f"the exact inverse model did not converge in {MAX_ITER} evaluations (r = {r!r}, "
        f"h = {h!r}, u = {u!r})"
    )


def inverse_input(
    params: BoucWenParams,
    reference: Reference,
    t: np.ndarray,
    *,
    h0: float = 0.0,
    allow_unbounded: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """The exact-inverse input along ``t`` and the hysteresis state after each jump.

    ``R = x_d'' + a2 x_d' + a1 x_d`` (in that order of operations), the first input
    ``(R_0 + a1 h0)/a3``, then :func:`inverse_step` per sample from the linear predictor.
    """
    require_bounded(params, allow_unbounded)
    t = np.asarray(t, dtype=float)
    a1, a2, a3 = params.a1, params.a2, params.a3
    pos, vel, acc = reference.evaluate(t)
    R = np.asarray(acc + a2 * vel + a1 * pos, dtype=float).reshape(t.shape)
    h_cap = inverse_bound(params)
    u = np.empty(t.shape)
    h = np.empty(t.shape)
    h_k = float(h0)
    u_k = (float(R.flat[0]) + a1 * h_k) / a3 if t.size else 0.0
    du = 0.0
    for k, r in enumerate(R.ravel().tolist()):
        try:
            v, h_k = inverse_step(params, h_k, u_k, r, u_k + du, h_cap)
        except InputError as err:
            raise InputError(f"at t = {float(t.flat[k]):.6g} s: {err}") from None
        du = v - u_k
        u_k = v
        u.flat[k], h.flat[k] = v, h_k
    if not (np.all(np.isfinite(u)) and math.isfinite(h_k)):
        raise InputError("the exact inverse model gives a non-finite input for this reference")
    return u, h
