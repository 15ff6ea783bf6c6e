"""LMI synthesis of observer gains certified for an input-rate envelope."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import GainError
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_sample_time, discretize
from ..validate import DECAY, POLE_RADIUS, UDOT_MAX, real
from .checks import (
    _lipschitz_coefficient,
    _model_matrix,
    _similar,
    continuous_equivalent,
    rho_interval,
    sector_interval,
)
from .results import _C, CertificateReport, SynthesisResult
from .tiers import _largest_decay, _largest_rate, _search_cap, certify, certify_discrete

__all__ = ["synthesize", "default_pole_radius"]


def default_pole_radius(params: BoucWenParams, dt: float | None = None) -> float:
    """Default pole-disk radius (rad/s) for :func:`synthesize`.

    ``10 sqrt(a1)`` (ten times the stage's natural frequency), and at most
    ``1/dt`` when a sample time is given, so that ``|lambda| dt <= 1``.
    """
    R = 10.0 * math.sqrt(params.a1)
    if dt is not None:
        R = min(R, 1.0 / dt)
    return R


def synthesize(
    params: BoucWenParams,
    *,
    udot_max: float,
    decay: float = 0.0,
    pole_radius: float | None = None,
    dt: float | None = None,
    allow_unbounded: bool = False,
) -> SynthesisResult:
    """Observer gains certified for ``|u'| <= udot_max`` with at least ``decay``.

    Without ``dt`` the ``sector`` LMI is solved in ``(P, Y = P l)`` with the
    observer poles in the disk ``|s| < pole_radius``. With ``dt`` the discrete
    ``sampled`` LMI is solved in ``(P, Y = P K)`` directly, with the nominal
    discrete poles in the disk ``|z - 1| < 1 - exp(-pole_radius dt)`` (the
    image of the continuous disk near ``z = 1``; it keeps every pole off the
    negative real axis, so the exact continuous equivalent of ``K`` exists and
    is reported as ``gains``). The LMI is solved twice: first for the largest
    margin ``t*`` (whose optimal set is not a single point), then for the
    smallest ``||Y||^2 + 0.01 ||P||_F^2`` with margin ``t*/2``: the least
    aggressive gains that keep half the best margin, a unique and reproducible
    design. Either way the result is re-certified by :func:`certify` before it
    is called feasible.

    Parameters
    ----------
    params : BoucWenParams
    udot_max : float
        Input-rate bound (V/s), > 0.
    decay : float
        Required decay rate (1/s), >= 0.
    pole_radius : float, optional
        Pole-disk radius (rad/s); default :func:`default_pole_radius`.
    dt : float, optional
        Sample time (s): synthesise the sampled observer.
    allow_unbounded : bool
        Accept a model outside the bounded class.

    Returns
    -------
    SynthesisResult
        ``feasible`` with gains and the re-certification, or ``feasible =
        False`` with ``binding`` naming the requirement that cannot be met and
        ``reason`` saying so in one sentence.

    Raises
    ------
    InputError
        ``udot_max``, ``decay``, ``pole_radius`` or ``dt`` out of range.

    Examples
    --------
    >>> from bwdesign import preset
    >>> res = synthesize(preset("paper_experiment"), udot_max=400.0, decay=50.0)
    >>> res.feasible
    True
    """
    require_bounded(params, allow_unbounded)
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_MAX)
    decay = real(decay, "decay (1/s)", within=DECAY)
    if dt is not None:
        dt = check_sample_time(params, dt)
    R = (
        default_pole_radius(params, dt)
        if pole_radius is None
        else real(pole_radius, "pole_radius (rad/s)", within=POLE_RADIUS)
    )
    if dt is None:
        return _synthesize_continuous(params, udot_max, decay, R, allow_unbounded)
    return _synthesize_sampled(params, udot_max, decay, R, dt, allow_unbounded)


@dataclass(frozen=True)
class _Attempt:
    ok: bool
    sol: Any
    t: float | None


def _attempt(sol: Any) -> _Attempt:
    t = float(sol["t"]) if sol.ok else None
    return _Attempt(bool(sol.ok and t is not None and t > 0), sol, t)


def _diagnose(
    params: BoucWenParams,
    attempt: Callable[[float, float, bool], _Attempt],
    *,
    tier: str,
    udot_max: float,
    decay: float,
    R: float,
    dt: float | None,
    first: _Attempt,
) -> SynthesisResult:
    """Name the binding requirement of an infeasible request."""
    common = dict(
        feasible=False,
        tier=tier,
        gains=None,
        discrete_gains=None,
        udot_max=udot_max,
        decay=decay,
        pole_radius=R,
        dt=dt,
        margin=first.t,
        solver=first.sol.solver,
        status=first.sol.status,
        report=None,
        params=params,
    )
    if not first.sol.ok and not isinstance(first.sol, _NoSolve):
        return SynthesisResult(
            binding="solver",
            reason=(
                f"the {tier} synthesis LMI was not solved ({'; '.join(first.sol.attempts)}); "
                "no gains are certified"
            ),
            max_decay=None,
            max_udot=None,
            **common,
        )
    where = f"within pole radius {R:g} rad/s at |u'| <= {udot_max:g} V/s ({tier} tier)"
    if decay > 0 and attempt(udot_max, 0.0, True).ok:
        cap = decay
        max_decay = _largest_decay(lambda m: attempt(udot_max, m, True).ok, cap)
        free = attempt(udot_max, decay, False).ok
        reason = (
            f"decay {decay:g} 1/s is not reachable {where}; the largest certifiable decay "
            f"there is {max_decay:.4g} 1/s"
        )
        if free:
            reason += "; without the pole region it is reachable, so a larger pole radius may help"
        return SynthesisResult(
            binding="pole_radius" if free else "decay",
            reason=reason,
            max_decay=max_decay,
            max_udot=None,
            **common,
        )
    cap = _search_cap(params)
    if dt is not None and _lipschitz_coefficient(params) > 0:
        cap = min(cap, 50.0 / (_lipschitz_coefficient(params) * dt))
    max_udot, _ = _largest_rate(lambda v: attempt(v, 0.0, True).ok, udot_max, min(cap, udot_max))
    if attempt(udot_max, 0.0, False).ok:
        return SynthesisResult(
            binding="pole_radius",
            reason=(
                f"no gains with poles within radius {R:g} rad/s certify |u'| <= {udot_max:g} V/s "
                f"({tier} tier; the largest certifiable within that radius is {max_udot:.4g} V/s); "
                "without the pole region they exist, so raise the pole radius"
            ),
            max_decay=None,
            max_udot=max_udot,
            **common,
        )
    return SynthesisResult(
        binding="udot_max",
        reason=(
            f"|u'| <= {udot_max:g} V/s cannot be certified by any gains at the {tier} tier "
            f"(within pole radius {R:g} rad/s the largest certifiable is {max_udot:.4g} V/s)"
        ),
        max_decay=None,
        max_udot=max_udot,
        **common,
    )


def _synthesize_continuous(
    params: BoucWenParams, udot_max: float, decay: float, R: float, allow_unbounded: bool
) -> SynthesisResult:
    from . import lmi

    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    A0h = _similar(_model_matrix(params), T) / w
    Ch = _C * T

    def attempt(v: float, m: float, disk: bool, t_min: float | None = None) -> _Attempt:
        k_lo, k_hi = sector_interval(params, v)
        sol = lmi.sector_synthesis(
            A0h,
            Ch,
            k_lo=k_lo / w,
            k_hi=k_hi / w,
            mu=m / w,
            radius=R / w if disk else None,
            t_min=t_min,
        )
        return _attempt(sol)

    first = attempt(udot_max, decay, True)
    if not first.ok:
        return _diagnose(
            params,
            attempt,
            tier="sector",
            udot_max=udot_max,
            decay=decay,
            R=R,
            dt=None,
            first=first,
        )
    design = _refine(first, lambda t_min: attempt(udot_max, decay, True, t_min))
    P = np.asarray(design.sol["P"])
    lh = np.linalg.solve((P + P.T) / 2, np.asarray(design.sol["Y"]).ravel())
    gains = tuple(float(x) for x in w * T * lh)
    return _finish(params, first, gains, None, "sector", udot_max, decay, R, None, allow_unbounded)


def _synthesize_sampled(
    params: BoucWenParams, udot_max: float, decay: float, R: float, dt: float, allow_unbounded: bool
) -> SynthesisResult:
    from . import lmi

    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    F = np.array(discretize(params, dt).F)
    Fh = _similar(F, T)
    Hh = F[0] * T
    disk = (1.0, -math.expm1(-R * dt))

    def attempt(v: float, m: float, with_disk: bool, t_min: float | None = None) -> _Attempt:
        lo, hi = rho_interval(params, v, dt)
        if not math.isfinite(hi):
            return _Attempt(False, _NoSolve(), None)
        sol = lmi.sampled_synthesis(
            Fh,
            Hh,
            rho_lo=lo,
            rho_hi=hi,
            r=math.exp(-m * dt),
            disk=disk if with_disk else None,
            t_min=t_min,
        )
        return _attempt(sol)

    first = attempt(udot_max, decay, True)
    if not first.ok:
        return _diagnose(
            params, attempt, tier="sampled", udot_max=udot_max, decay=decay, R=R, dt=dt, first=first
        )
    design = _refine(first, lambda t_min: attempt(udot_max, decay, True, t_min))
    P = np.asarray(design.sol["P"])
    Kh = np.linalg.solve((P + P.T) / 2, np.asarray(design.sol["Y"]).ravel())
    K = tuple(float(x) for x in T * Kh)
    gains = continuous_equivalent(params, K, dt)
    return _finish(params, first, gains, K, "sampled", udot_max, decay, R, dt, allow_unbounded)


#: The refinement keeps this fraction of the best synthesis margin.
REFINE_MARGIN_FRACTION = 0.5


def _refine(first: _Attempt, solve: Callable[[float], _Attempt]) -> _Attempt:
    """Second stage: the smallest gains keeping half the best margin (a unique point).

    Falls back to the max-margin design if the refinement is not solved.
    """
    refined = solve(REFINE_MARGIN_FRACTION * float(first.t))
    return refined if refined.sol.ok else first


class _NoSolve:
    """Stand-in solution for a request that needs no solver to say no."""

    ok = False
    status = "not_solved"
    solver = ""
    attempts = ("rho interval unbounded at this rate",)


#: Synthesised gains are rounded to this many significant digits before re-certification.
SIGNIFICANT_DIGITS = 7


def _round_sig(values: tuple[float, ...] | None) -> tuple[float, ...] | None:
    if values is None:
        return None
    return tuple(float(f"{v:.{SIGNIFICANT_DIGITS}g}") for v in values)


def _finish(
    params: BoucWenParams,
    first: _Attempt,
    gains: tuple[float, float, float] | None,
    K: tuple[float, float, float] | None,
    tier: str,
    udot_max: float,
    decay: float,
    R: float,
    dt: float | None,
    allow_unbounded: bool,
) -> SynthesisResult:
    # Round to SIGNIFICANT_DIGITS before re-certifying: the certificate is then
    # about exactly the numbers reported (and pasted into firmware), and the
    # solver's last-digit noise does not reach the report.
    gains = _round_sig(gains)
    K = _round_sig(K)
    report: CertificateReport | None = None
    problem = ""
    if gains is not None:
        try:
            report = certify(
                params,
                gains,
                udot_max=udot_max,
                decay=decay,
                dt=dt,
                allow_unbounded=allow_unbounded,
            )
        except GainError as err:
            problem = str(err)
    if report is None and K is not None:
        report = certify_discrete(
            params, K, udot_max=udot_max, dt=dt, decay=decay, allow_unbounded=allow_unbounded
        )
    holds = report is not None and report.tier(tier).holds
    if report is not None and report.discrete_gains is not None:
        K = report.discrete_gains
    if holds:
        what = f"gains l = ({', '.join(f'{g:.6g}' for g in gains)})" if gains else "discrete gains"
        reason = (
            f"{what} certified by the {tier} tier for |u'| <= {udot_max:g} V/s with decay "
            f">= {decay:g} 1/s, poles within {R:g} rad/s"
        )
        if tier == "sampled" and gains is None:
            reason += "; the discrete poles have no exact continuous equivalent"
    else:
        reason = "the synthesised gains did not pass re-certification" + (
            f": {problem}" if problem else f" ({report.tier(tier).status})" if report else ""
        )
    return SynthesisResult(
        feasible=holds,
        tier=tier,
        gains=gains,
        discrete_gains=K,
        udot_max=udot_max,
        decay=decay,
        pole_radius=R,
        dt=dt,
        binding=None if holds else "verification",
        reason=reason,
        max_decay=None,
        max_udot=None,
        margin=first.t,
        solver=first.sol.solver,
        status=first.sol.status,
        report=report,
        params=params,
    )
