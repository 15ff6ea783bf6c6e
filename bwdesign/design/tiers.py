"""Gain synthesis for the ``theorem1`` and ``lipschitz`` tiers (``synthesize(..., tier=...)``).

Both LMIs are solved in ``(X, Z = X l^)`` in scaled coordinates: state
``eps^ = S eps`` with ``S = diag(1, 1/w0, 1)``, ``w0 = sqrt(a1)``, and time
``tau = w0 t``, so that ``A^ = S A0 S^-1 / w0 = [[0, 1, 0], [-1, -a2/w0, -1], [0, 0, 0]]``
has O(1) entries for every stage (a1 spans 1e3..1e9).

``theorem1``
    The paper's Theorem 1 with the sign corrected, in the norm ``||S eps||``:
    ``He(X A^_cl) + 2 (mu/w0) X <= -I`` means ``V = eps^' X eps^`` has
    ``V' <= -(w0 - 2 L ||X||) ||eps^||^2`` (``|phi~| <= L |eps3| <= L ||eps^||``
    since ``S`` keeps ``eps3``), so the envelope is ``w0 / (2 c ||X||)`` with
    ``c = |beta| + |gamma|``; the LMI minimises ``||X||``. This scaled norm is the
    state scaling chosen for the theorem: :func:`certify`'s ``theorem1`` tier uses
    the unscaled norm, and the result's ``report`` says what that gives for the
    same gains.
``lipschitz``
    The S-procedure LMI ``[[He(X A^_cl) + 2 mu^ X + L^^2 e3 e3', X e3], [e3' X, -1]] < 0``
    (``mu^ = mu/w0``, ``L^ = L/w0``), bisected on ``L`` for the largest feasible;
    the gains are re-certified by :func:`certify`'s ``lipschitz`` tier (exact).

A ``pole_radius`` is a constraint of either LMI (the error poles in the disk
``|s| <= R``, with the same ``X``) and is measured on the returned gains outside the
solver (``pole_check``); without one there is no pole region. A ``dt`` maps the gains
to the discrete gain the sampled observer runs (pole matching, as every tier does) and
re-certifies them with the ``sampled`` tier; feasible then needs that tier too.

Every ``X`` is re-checked with ``numpy.linalg.eigvalsh`` outside the solver; solver
trouble is never a design.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..certify.checks import lipschitz_coefficient
from ..certify.results import TIERS, Margin, SynthesisResult
from ..certify.tiers import certify
from ..model.params import BoucWenParams
from ..observers.gains import error_matrix

__all__ = ["synthesize_tier", "recertify_sampled"]

#: Bound on the scaled gain ``||Z|| <= LMAX ||X||`` (``l^ = X^-1 Z`` in units of ``w0``):
#: the analogue of the default pole radius ``10 sqrt(a1)``.
LMAX = 10.0


def _scaled(params: BoucWenParams) -> tuple[float, np.ndarray, np.ndarray]:
    w0 = math.sqrt(params.a1)
    s = np.array([1.0, 1.0 / w0, 1.0])
    Ahat = np.array([[0.0, 1.0, 0.0], [-1.0, -params.a2 / w0, -1.0], [0.0, 0.0, 0.0]])
    return w0, s, Ahat


def _gains(X: np.ndarray, Z: np.ndarray, w0: float, s: np.ndarray) -> tuple[float, float, float]:
    lt = np.linalg.solve(X, np.asarray(Z, float).reshape(3))
    l = w0 * lt / s
    return float(l[0]), float(l[1]), float(l[2])


def _cl(params: BoucWenParams, gains, w0: float, s: np.ndarray) -> np.ndarray:
    A = error_matrix(params, gains)
    return s[:, None] * A / s[None, :] / w0


def _refused(params, tier, udot_max, decay, R, dt, status) -> SynthesisResult:
    return SynthesisResult(
        feasible=False,
        tier=tier,
        gains=None,
        discrete_gains=None,
        udot_max=udot_max,
        decay=decay,
        pole_radius=R,
        dt=dt,
        binding="udot_max",
        reason=f"no {tier} design: {status}",
        max_decay=None,
        max_udot=0.0,
        margin=None,
        solver="",
        status=status,
        report=None,
        params=params,
    )


def _pole_check(params: BoucWenParams, gains, R: float) -> Margin | None:
    """The requested pole disk measured on the returned gains (``None``: no disk asked)."""
    if gains is None or not math.isfinite(R):
        return None
    lam = np.linalg.eigvals(error_matrix(params, gains))
    return Margin("max |lambda| (rad/s)", float(np.max(np.abs(lam))), R)


def _theorem1(params, w0, s, Ahat, c, udot_max, mu, radius):
    """``(gains, envelope, margin, solver, status)`` of the Theorem-1 synthesis."""
    from ..certify import lmi

    sol = lmi.theorem1_synthesis(Ahat, mu=mu, lmax=LMAX, radius=radius)
    if not sol.ok:
        return None, 0.0, None, sol.solver, sol.status
    X = (np.asarray(sol["X"]) + np.asarray(sol["X"]).T) / 2
    gains = _gains(X, np.asarray(sol["Z"]), w0, s)
    Acl = _cl(params, gains, w0, s)
    M = X @ Acl + Acl.T @ X + 2 * mu * X
    q = -float(np.linalg.eigvalsh((M + M.T) / 2).max())
    nX = float(np.linalg.eigvalsh(X).max())
    pos = float(np.linalg.eigvalsh(X).min()) > 0
    # outside check: envelope w0 q / (2 c ||X||) in the scaled norm
    envelope = w0 * q / (2 * c * nX) if (pos and q > 0 and c > 0) else 0.0
    margin = Margin("2 L ||X|| < w0 q (scaled norm)", 2 * c * udot_max * nX, w0 * q)
    return gains, envelope, margin, sol.solver, sol.status


def _lipschitz(w0, s, Ahat, c, udot_max, mu, radius):
    """``(gains, solver, status)`` of the lipschitz synthesis (bisection on ``L``)."""
    from ..certify import lmi

    def feasible(L: float):
        sol = lmi.lipschitz_synthesis(Ahat, L=L / w0, mu=mu, lmax=LMAX, radius=radius)
        return sol if sol.ok and float(sol["t"]) > 0 else None

    lo, hi, best = 0.0, c * udot_max, None
    while (cand := feasible(hi)) is not None and hi < 1e6 * w0:
        lo, best, hi = hi, cand, hi * 4
    for _ in range(30):
        if hi / max(lo, 1e-300) < 1.01:
            break
        mid = math.sqrt(lo * hi) if lo > 0 else hi / 4
        cand = feasible(mid)
        if cand is not None:
            lo, best = mid, cand
        else:
            hi = mid
    if best is None:
        return None, "", "infeasible at every L tried"
    X = (np.asarray(best["X"]) + np.asarray(best["X"]).T) / 2
    return _gains(X, np.asarray(best["Z"]), w0, s), best.solver, best.status


def synthesize_tier(
    params: BoucWenParams,
    tier: str,
    *,
    udot_max: float,
    decay: float,
    pole_radius: float | None = None,
    dt: float | None = None,
    allow_unbounded: bool = False,
) -> SynthesisResult:
    """Synthesise gains for ``tier`` in ``("theorem1", "lipschitz")`` (see the module doc).

    ``pole_radius`` (rad/s), when given, is a constraint of the LMI (the error poles
    in ``|s| <= pole_radius``) and is measured on the returned gains (``pole_check``);
    without it there is no pole region (the LMIs bound the scaled gain instead).
    ``dt`` (s) maps the gains to the discrete gain the sampled observer runs and
    re-certifies them with the ``sampled`` tier too; feasible needs both to hold.
    """
    w0, s, Ahat = _scaled(params)
    c = lipschitz_coefficient(params)
    mu = decay / w0
    R = math.inf if pole_radius is None else float(pole_radius)
    radius = None if pole_radius is None else R / w0
    margin: Margin | None = None
    try:
        if tier == "theorem1":
            gains, envelope, margin, solver, status = _theorem1(
                params, w0, s, Ahat, c, udot_max, mu, radius
            )
        else:
            gains, solver, status = _lipschitz(w0, s, Ahat, c, udot_max, mu, radius)
            envelope = 0.0
    except ValueError as err:  # gains out of the supported range: not a design
        return _refused(params, tier, udot_max, decay, R, dt, str(err))
    report = None
    if gains is not None:
        try:
            report = certify(
                params,
                gains,
                udot_max=udot_max,
                decay=decay,
                dt=dt,
                tiers=(tier,) if dt is None else (tier, "sampled"),
                allow_unbounded=allow_unbounded,
            )
        except ValueError as err:  # the gains break the Hurwitz conditions: not a design
            status = f"{status}; re-certification refused the gains: {err}"
            gains = None
    if tier == "lipschitz" and report is not None:
        envelope = report.tier("lipschitz").max_udot
    return _conclude(
        params, tier, gains, report, envelope, margin, (udot_max, decay, R, dt), solver, status
    )


def _conclude(params, tier, gains, report, envelope, margin, request, solver, status):
    udot_max, decay, R, dt = request
    holds = gains is not None and udot_max < envelope
    if tier == "theorem1":
        holds = holds and margin is not None and margin.passed
    disk = _pole_check(params, gains, R)
    binding = None if holds else "udot_max"
    if gains is not None:
        reason = f"gains {gains} reach |u'| <= {envelope:.6g} V/s for the {tier} tier"
    elif math.isfinite(R):  # not even a vanishing envelope fits the disk (and the decay)
        binding = "pole_radius"
        reason = f"no {tier} design with poles within {R:g} rad/s, decay >= {decay:g} 1/s: {status}"
    else:
        reason = f"no {tier} design: {status}"
    if holds and disk is not None and not disk.passed:
        holds, binding = False, "pole_radius"
        reason += f", but their poles leave the disk: {disk.name} = {disk.value:.6g} >= {R:g}"
    elif holds and disk is not None:
        reason += f", poles within {R:g} rad/s (checked: {disk.name} = {disk.value:.6g})"
    K = None if report is None else report.discrete_gains
    if holds and dt is not None:
        smp = report.tier("sampled")
        reason += f"; the observer sampled at dt = {dt:g} s (K = {K}): {smp.status}"
        if not smp.holds:
            holds, binding = False, "verification"
    return SynthesisResult(
        feasible=holds,
        tier=tier,
        gains=gains if holds else None,
        discrete_gains=K if holds else None,
        udot_max=udot_max,
        decay=decay,
        pole_radius=R,
        dt=dt,
        binding=binding,
        reason=reason,
        max_decay=None,
        max_udot=envelope,
        margin=None if margin is None else margin.limit - margin.value,
        solver=solver,
        status=status,
        report=report,
        params=params,
        pole_check=disk,
    )


def recertify_sampled(res: SynthesisResult, dt: float, allow_unbounded: bool) -> SynthesisResult:
    """A continuous (``sector``) design run sampled at ``dt``: its discrete gain and the
    ``sampled`` re-certification, which a feasible answer then needs too."""
    if not res.feasible:
        return replace(res, dt=dt)
    kept = res.report
    continuous = TIERS[:3]
    # the continuous tiers do not depend on dt: when they are at hand only the sampled
    # one is new (the report is the one certify(..., dt=dt) returns, computed once)
    reuse = (
        kept is not None
        and kept.dt is None
        and tuple(c.name for c in kept.certificates) == continuous
    )
    report = certify(
        res.params,
        res.gains,
        udot_max=res.udot_max,
        decay=res.decay,
        dt=dt,
        allow_unbounded=allow_unbounded,
        **({"tiers": ("sampled",)} if reuse else {}),
    )
    if reuse:
        report = replace(
            kept,
            dt=dt,
            discrete_gains=report.discrete_gains,
            certificates=kept.certificates + report.certificates,
        )
    smp = report.tier("sampled")
    K = report.discrete_gains
    reason = f"{res.reason}; the observer sampled at dt = {dt:g} s (K = {K}): {smp.status}"
    if smp.holds:
        return replace(res, dt=dt, discrete_gains=K, report=report, reason=reason)
    return replace(res, feasible=False, dt=dt, binding="verification", reason=reason, report=report)
