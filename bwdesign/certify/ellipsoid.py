"""What the two robust certificates share: the Schur-block check and the contraction search.

Both :mod:`bwdesign.certify.robust` (the tracking loop) and
:mod:`bwdesign.certify.robust_observer` (the observer error) certify an invariant
ellipsoid ``V(z+) <= a V(z) + (1 - a) sum lam_j w_j^2`` with
:func:`bwdesign.certify.lmi.robust_ellipsoid`-type programs, re-check every block
outside the solver and search the contraction ``a`` on ``x = log(1 - a)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..model.params import BoucWenParams

__all__ = [
    "solution",
    "schur_min_eig",
    "search_log_contraction",
    "jump_mismatch",
    "disturbance_remainder",
    "copy_error_bound",
]


def disturbance_remainder(a3: float, rate_max: float, dt: float) -> np.ndarray:
    """Bounds on what an input disturbance moving within a sample adds to the held one.

    The plant's linear part gains ``r = int_0^dt e^{A(dt - s)} b (d(t_k + s) - d_k) ds``
    over sample ``k`` (``b = (0, a3)``, ``|d(t_k + s) - d_k| <= rate_max s``) beside its
    ZOH step with ``d_k`` held. With ``a1 > 0`` and ``a2 >= 0`` the energy ``a1 x1^2 +
    x2^2`` of ``x' = A x`` does not grow, so ``|(e^{A tau} b)_2| <= |a3|`` and
    ``|(e^{A tau} b)_1| <= |a3| tau``: ``|r1| <= rate_max |a3| dt^3 / 6`` and ``|r2| <=
    rate_max |a3| dt^2 / 2``.
    """
    a3 = abs(a3)
    return np.array([rate_max * a3 * dt**3 / 6, rate_max * a3 * dt**2 / 2])


def solution(sol: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(Q, lam)`` of a solved ellipsoid program: ``Q`` symmetrised, ``lam >= 0``."""
    Q = np.asarray(sol["Q"])
    return (Q + Q.T) / 2, np.maximum(np.asarray(sol["lam"]), 0.0)


def schur_min_eig(Q: np.ndarray, lam: np.ndarray, A: np.ndarray, B: np.ndarray, a: float) -> float:
    """Smallest eigenvalue of one diagonally normalised Schur block of the LMI (> 0 passes)."""
    n, m = Q.shape[0], lam.size
    M = np.block(
        [
            [a * Q, np.zeros((n, m)), Q @ A.T],
            [np.zeros((m, n)), (1 - a) * np.diag(lam), B.T],
            [A @ Q, B, Q],
        ]
    )
    M = (M + M.T) / 2
    dg = np.sqrt(np.maximum(np.abs(np.diag(M)), 1e-300))
    return float(np.linalg.eigvalsh(M / np.outer(dg, dg)).min())


def search_log_contraction(
    f: Callable[[float], float],
    grid: Sequence[float],
    iters: int,
    *,
    lo: float | None = None,
    hi: float | None = None,
) -> None:
    """Minimise ``f`` over ``x = log(1 - a)``: the grid, then golden section around its best.

    The grid first, because the program is badly conditioned as ``a -> 1`` and
    infeasible near ``a = spectral radius^2``: a solver failure (``f = inf``) would
    mislead a golden-section search started on the whole interval. The bracket is
    the best grid point's neighbours (``lo``/``hi`` beyond the grid's first and
    last point; by default the grid ends). ``f`` caches its own results.
    """
    vals = [f(float(x)) for x in grid]
    i = int(np.argmin(vals))
    if not math.isfinite(vals[i]):
        return
    left = float(grid[i - 1]) if i > 0 else float(grid[0] if lo is None else lo)
    right = float(grid[i + 1]) if i + 1 < len(grid) else float(grid[-1] if hi is None else hi)
    lo_, hi_ = sorted((left, right))
    g = (math.sqrt(5) - 1) / 2
    x1, x2 = hi_ - g * (hi_ - lo_), lo_ + g * (hi_ - lo_)
    for _ in range(iters):
        if f(x1) <= f(x2):
            hi_, x2 = x2, x1
            x1 = hi_ - g * (hi_ - lo_)
        else:
            lo_, x1 = x1, x2
            x2 = lo_ + g * (hi_ - lo_)


def jump_mismatch(model: BoucWenParams, tp: BoucWenParams, du: float) -> float:
    """Bound of ``|Hm(x3) - Hv(x3)|`` for ``|x3| <= h_max`` and ``|du|`` (Gronwall; may be inf)."""
    H = max(model.bounded_class().h_max, tp.bounded_class().h_max)
    df = abs(model.alpha - tp.alpha) + (abs(model.beta - tp.beta) + abs(model.gamma - tp.gamma)) * H
    if df == 0:
        return 0.0
    x = (abs(model.beta) + abs(model.gamma)) * du
    return df * du * math.exp(x) if x < 700 else math.inf


def copy_error_bound(model: BoucWenParams, tp: BoucWenParams) -> float:
    """Bound of ``|x3hat - x3|`` for a hysteresis copy on ``model`` and the plant ``tp``
    driven by the same input and started together.

    Along the input's path length ``s`` (``ds = |du|``, so the ZOH jump maps too),
    ``dx/ds = alpha sgn - beta x - gamma sgn |x|`` has the one-sided Lipschitz constant
    ``-(beta - |gamma|)``, and the two right-hand sides differ at the plant's ``x3``
    by at most ``|dalpha| + (|dbeta| + |dgamma|) h_max(plant)``: so ``d|e|/ds <=
    -(beta_m - |gamma_m|) |e| + D`` and ``|e| <= D / (beta_m - |gamma_m|)`` is
    invariant (likewise with the roles swapped). Never above ``h_max(model) +
    h_max(plant)`` (both copies stay in their own range).
    """
    hm, hp = model.bounded_class().h_max, tp.bounded_class().h_max
    da = abs(model.alpha - tp.alpha)
    dbg = abs(model.beta - tp.beta) + abs(model.gamma - tp.gamma)
    best = math.inf
    for kappa, h in ((model.beta - abs(model.gamma), hp), (tp.beta - abs(tp.gamma), hm)):
        if kappa > 0:
            best = min(best, (da + dbg * h) / kappa)
    return min(best, hm + hp)
