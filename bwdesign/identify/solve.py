"""Levenberg-Marquardt on the output error, with the offset in closed form and a
convergence test about the fit.

The sensor offset enters the residual as a constant column, so for any other
coordinates its best value is the mean misfit: the solver keeps it there
(variable projection, the residual and the Jacobian centred) and never steps
along it. Offset, gain and hysteresis then cannot trade off along a valley.

Converged means: the Gauss-Newton step from the current point would move the fit
by less than :data:`STEP_TOL` of a standard error in every direction the record
determines (the projection of the residual on each left singular vector of the
column-scaled Jacobian, over the white-noise ``sigma``); the predicted misfit
decrease is then below ``STEP_TOL**2`` noise variances per direction. A
direction the record does not determine has a large standard error, so a large
move along it is still a small step: it is reported by the intervals, never a
reason to keep iterating. ``max_nfev`` only caps the work.

Where the model misses part of the behaviour (creep, an amplifier lag), the
residual is large and coloured and the Gauss-Newton model of the misfit is poor:
the linearised step stays large while no step of the damped iteration lowers the
misfit by anything the data could tell apart. The fit is then stationary:
converged too, when the misfit fell by less than :data:`STATIONARY_FALL` noise
variances over the last :data:`STATIONARY_STEPS` accepted steps (a change of the
fit far below its own scatter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .problem import Problem
from .stack import Stack

__all__ = ["Solution", "solve", "STEP_TOL"]

#: Largest Gauss-Newton step (in standard errors, per determined direction) at convergence.
STEP_TOL = 0.05
#: Stationary misfit: over this many accepted steps ...
STATIONARY_STEPS = 10
#: ... the sum of squared residuals fell by less than this many noise variances.
STATIONARY_FALL = 0.1
#: Singular values below this fraction of the largest span no direction (rounding).
_RANK_TOL = 1e-10


@dataclass
class Solution:
    """What :func:`solve` found: ``cost`` is half the sum of squared scaled residuals.

    ``status`` > 0 converged (1: the step test, 2: no step lowers the misfit and the
    remaining step is below a standard error), 0 not converged; ``step`` is the last
    Gauss-Newton step in standard errors (largest over determined directions).
    """

    cost: float
    nfev: int
    njev: int
    status: int
    message: str
    step: float


def solve(
    prob: Problem | Stack,
    theta0: np.ndarray,
    free: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    *,
    max_nfev: int = 200,
    step_tol: float = STEP_TOL,
) -> tuple[np.ndarray, Solution]:
    """Minimise the misfit over the ``free`` coordinates of ``theta0`` (offsets projected).

    ``prob``: one record's problem or a :class:`~bwdesign.identify.stack.Stack` of
    several (each record's offset projected out). ``bounds`` are full-length lower
    and upper limits; a coordinate on its limit with the descent pointing outside
    is held for that iteration.
    """
    if isinstance(prob, Problem):
        prob = Stack([prob])
    lo, hi = bounds
    offset = np.zeros(free.size, dtype=bool)
    offset[prob.i_off] = True
    idx = np.flatnonzero(free & ~offset)
    jfree = np.zeros_like(free)
    jfree[idx] = True
    theta, r = prob.project_offsets(np.clip(theta0, lo, hi))
    nfev, njev, cost = 1, 0, 0.5 * float(r @ r)
    if not math.isfinite(cost):
        return theta, Solution(cost, nfev, njev, 0, "the start is not finite", math.inf)
    lam, crit = None, math.inf
    n = r.size
    accepted = [cost]
    while True:
        jac = prob.jacobian(theta, jfree)
        njev += 1
        jac = prob.centre(jac)
        grad = jac.T @ r
        x = theta[idx]
        keep = ~(((x <= lo[idx] + 1e-12) & (grad > 0)) | ((x >= hi[idx] - 1e-12) & (grad < 0)))
        jk = jac[:, keep]
        scale = np.linalg.norm(jk, axis=0)
        scale[scale == 0] = 1.0
        u, s, vt = np.linalg.svd(jk / scale, full_matrices=False)
        ok = s > s[0] * _RANK_TOL if s.size and s[0] > 0 else np.zeros(s.size, dtype=bool)
        proj = u[:, ok].T @ r
        sigma = math.sqrt(2.0 * cost / max(1, n - int(ok.sum()) - prob.n_records)) or 1e-300
        crit = float(np.max(np.abs(proj))) / sigma if proj.size else 0.0
        if crit < step_tol:
            return theta, Solution(cost, nfev, njev, 1, _msg(crit), crit)
        s, vt = s[ok], vt[ok]
        if lam is None:
            lam = 1e-3 * s[0] ** 2
        while True:
            if nfev >= max_nfev:
                return theta, Solution(
                    cost,
                    nfev,
                    njev,
                    0,
                    f"the optimiser used its {nfev} residual evaluations with the last "
                    f"Gauss-Newton step still {crit:.3g} standard errors (tolerance "
                    f"{step_tol:g})",
                    crit,
                )
            step = -(vt.T @ (s / (s * s + lam) * proj)) / scale
            trial = theta.copy()
            trial[idx[keep]] = np.clip(x[keep] + step, lo[idx[keep]], hi[idx[keep]])
            trial, rt = prob.project_offsets(trial)
            nfev += 1
            ct = 0.5 * float(rt @ rt)
            if math.isfinite(ct) and ct < cost:
                theta, r, cost = trial, rt, ct
                lam = max(lam / 5.0, 1e-12 * s[0] ** 2)
                accepted.append(cost)
                fell = _stationary(accepted, sigma)
                if fell is not None:
                    return theta, Solution(cost, nfev, njev, 3, _msg_stationary(fell), crit)
                break
            lam *= 4.0
            if lam > 1e12 * s[0] ** 2:
                # no step lowers the misfit: stationary to rounding
                status = 2 if crit < 1.0 else 0
                return theta, Solution(
                    cost,
                    nfev,
                    njev,
                    status,
                    f"no step lowers the misfit (last Gauss-Newton step {crit:.3g} standard "
                    "errors)",
                    crit,
                )


def _stationary(accepted: list[float], sigma: float) -> float | None:
    """The misfit's fall over the last :data:`STATIONARY_STEPS` accepted steps, in noise
    variances, when it is below :data:`STATIONARY_FALL` (else None)."""
    if len(accepted) <= STATIONARY_STEPS:
        return None
    fell = (accepted[-STATIONARY_STEPS - 1] - accepted[-1]) / (0.5 * sigma * sigma)
    return fell if fell < STATIONARY_FALL else None


def _msg_stationary(fell: float) -> str:
    return (
        f"converged: the misfit is stationary (it fell by {fell:.2g} noise variances over "
        f"the last {STATIONARY_STEPS} steps, tolerance {STATIONARY_FALL:g}); the linearised "
        "step is larger than the fit's scatter supports, as where the model misses part of "
        "the behaviour"
    )


def _msg(crit: float) -> str:
    return (
        f"converged: the Gauss-Newton step is {crit:.2g} standard errors in every "
        f"direction the record determines (tolerance {STEP_TOL:g})"
    )
