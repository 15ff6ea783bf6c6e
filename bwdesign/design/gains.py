"""LMI synthesis of observer gains certified for an input-rate envelope."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..certify.checks import (
    continuous_equivalent,
    lipschitz_coefficient,
    model_matrix,
    prepare_sampled,
    rho_exponents,
    rho_interval,
    scale_continuous,
    sector_interval,
    similar,
)
from ..certify.frequency import continuous_family, sampled_family
from ..certify.results import K_HAT_CAP, OUTPUT_ROW, CertificateReport, Margin, SynthesisResult
from ..certify.tiers import certify, certify_discrete, largest_decay, largest_rate
from ..errors import GainError, InputError
from ..memo import Memo
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_sample_time, discretize
from ..observers.gains import check_gains, delta_transition, discrete_gains, error_matrix
from ..validate import DECAY, POLE_RADIUS, UDOT_MAX, real

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
    tier: str | None = None,
    explain: bool = True,
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
    is called feasible, and the pole region is measured on the returned gains
    outside the solver (``pole_check``: ``max |lambda|`` against ``pole_radius``
    in continuous time, ``max |z - 1|`` against ``1 - exp(-pole_radius dt)`` with
    ``dt``); a design that leaves the region is not feasible.

    When the LMI design is infeasible or rejected, a fixed set of pole patterns
    (magnitudes ``sqrt(a1) 2^(k/2)``, four shapes) inside the region is searched
    with the exact frequency-domain criterion, and the best ones are certified.
    Monotonicity in the radius: the pattern set of a larger radius contains that
    of a smaller one, so an answer found by the search stays feasible for every
    larger radius; an answer found only by the LMI (whose solution depends on
    the radius) is not guaranteed to be found again for a larger one, but the
    search then still runs. A "no" names the binding requirement with the
    numbers the exact criterion gives over the searched patterns.

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
    tier : {"theorem1", "lipschitz", "sector", "sampled"}, optional
        The tier to synthesise for; default ``sector`` without ``dt``, ``sampled``
        with it (the behaviour above). ``theorem1`` and ``lipschitz`` are the
        continuous LMIs of :mod:`bwdesign.design.tiers` (``max_udot`` is
        the envelope the synthesised gains reach): a given ``pole_radius`` is an LMI
        constraint and is measured on the gains (no default region for them), and
        ``dt`` adds the discrete gains and the ``sampled`` re-certification, which
        feasibility then needs too.
    explain : bool
        ``False``: a "no" of the ``sector`` or ``sampled`` synthesis does not look
        for the binding requirement (``binding = "unexplained"``, no
        ``max_decay``/``max_udot``), which is most of the time of a "no"; for
        searches that only need to know whether gains were found. A "yes" is the
        same either way.

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
    if pole_radius is not None:
        pole_radius = real(pole_radius, "pole_radius (rad/s)", within=POLE_RADIUS)
    if tier is not None and tier not in ("theorem1", "lipschitz", "sector", "sampled"):
        raise InputError(f"unknown tier {tier!r}; tiers are theorem1, lipschitz, sector, sampled")
    if tier == "sampled" and dt is None:
        raise InputError("the sampled tier needs the sample time dt (s)")
    args = (params, udot_max, decay, pole_radius, dt, allow_unbounded, tier, bool(explain))
    return _SYNTHESISED.get(args, lambda: _synthesize(*args))


#: :func:`synthesize`'s results kept by their exact (checked) arguments, in this process
#: (a pure function of them; the report's tier searches and the commands ask again).
_SYNTHESISED: Memo[SynthesisResult] = Memo(32)


def _synthesize(
    params: BoucWenParams,
    udot_max: float,
    decay: float,
    pole_radius: float | None,
    dt: float | None,
    allow_unbounded: bool,
    tier: str | None,
    explain: bool,
) -> SynthesisResult:
    """:func:`synthesize` of checked arguments."""
    R = default_pole_radius(params, dt) if pole_radius is None else pole_radius
    if tier in ("theorem1", "lipschitz"):
        from .tiers import synthesize_tier

        return synthesize_tier(
            params,
            tier,
            udot_max=udot_max,
            decay=decay,
            pole_radius=pole_radius,
            dt=dt,
            allow_unbounded=allow_unbounded,
        )
    if dt is None or tier == "sector":
        res = _synthesize_continuous(params, udot_max, decay, R, allow_unbounded, explain)
        if dt is None:
            return res
        from .tiers import recertify_sampled

        return recertify_sampled(res, dt, allow_unbounded)
    return _synthesize_sampled(params, udot_max, decay, R, dt, allow_unbounded, explain)


@dataclass(frozen=True)
class _Attempt:
    ok: bool
    sol: Any
    t: float | None


def _attempt(sol: Any) -> _Attempt:
    t = float(sol["t"]) if sol.ok else None
    return _Attempt(bool(sol.ok and t is not None and t > 0), sol, t)


def _pole_disk(
    params: BoucWenParams,
    gains: tuple[float, float, float] | None,
    K: tuple[float, float, float] | None,
    R: float,
    dt: float | None,
) -> Margin:
    """The requested pole region, measured on the returned gains (outside the solver).

    Continuous: ``max |lambda_i| < R`` for the eigenvalues of ``A0 - l C``.
    Sampled: the discrete poles ``z_i`` of ``(I - K C) F`` in ``|z - 1| < 1 - exp(-R dt)``,
    with ``z_i - 1 = dt delta_i`` from the delta form (no cancellation).
    """
    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    if dt is None:
        if gains is None:
            return Margin("max |pole| (rad/s)", math.inf, R)
        lam = np.linalg.eigvals(similar(error_matrix(params, gains), T) / w) * w
        return Margin("max |pole| of A0 - l C (rad/s)", float(np.max(np.abs(lam))), R)
    if K is None:
        return Margin("max |z - 1|", math.inf, -math.expm1(-R * dt))
    F, Fd = delta_transition(params, dt)
    Ad1 = Fd - np.outer(np.asarray(K) / dt, F[0])
    d = np.linalg.eigvals(similar(Ad1, T) / w) * w
    return Margin(
        "max |z - 1| of the discrete poles", float(dt * np.max(np.abs(d))), -math.expm1(-R * dt)
    )


#: Pole patterns of the exact search, as multiples of a magnitude ``m``: a real
#: triple, two damped pairs with a real pole, and a slow real pole with a pair.
_SHAPES = (
    np.array([1.0, 1.0, 1.0]),
    np.array([1.0, 0.7 + 0.714j, 0.7 - 0.714j]),
    np.array([1.0, 0.3 + 0.954j, 0.3 - 0.954j]),
    np.array([0.1, 0.7 + 0.714j, 0.7 - 0.714j]),
)
#: Magnitudes of the exact search: ``sqrt(a1) 2^(k/2)``, ``k = -SEARCH_OCTAVES .. SEARCH_OCTAVES``.
SEARCH_OCTAVES = 24


@dataclass(frozen=True)
class _Candidate:
    gains: tuple[float, float, float]
    poles: np.ndarray
    radius: float  # the smallest request radius (rad/s) whose region contains the poles


def _candidates(params: BoucWenParams, dt: float | None) -> list[_Candidate]:
    """A fixed set of pole patterns (independent of the request's radius)."""
    w0 = math.sqrt(params.a1)
    out = []
    for k in range(-SEARCH_OCTAVES, SEARCH_OCTAVES + 1):
        m = w0 * 2.0 ** (k / 2)
        for shape in _SHAPES:
            lam = -m * shape
            c = np.real(np.poly(lam))
            l1 = c[1] - params.a2
            l2 = c[2] - params.a1 - l1 * params.a2
            l3 = -c[3] / params.a1
            if dt is None:
                radius = float(np.max(np.abs(lam)))
            else:
                zm1 = float(np.max(np.abs(_expm1c(lam * dt))))
                radius = math.inf if zm1 >= 1.0 else -math.log1p(-zm1) / dt
            out.append(_Candidate((float(l1), float(l2), float(l3)), lam, radius))
    return out


def _expm1c(x: np.ndarray) -> np.ndarray:
    a, b = x.real, x.imag
    return np.expm1(a) * np.cos(b) - 2.0 * np.sin(b / 2.0) ** 2 + 1j * np.exp(a) * np.sin(b)


def _exact_score(
    params: BoucWenParams,
    gains: tuple[float, float, float],
    v: float,
    mu: float,
    dt: float | None,
    sign_only: bool = True,
) -> float:
    """Exact margin of the tier's criterion at ``(v, mu)``: > 0 when a certificate exists.

    ``sign_only``: a positive margin is exact, a non-positive one is some number <= 0
    (the frequency search stops once the margin cannot be positive); ``False`` for
    the exact margin whatever its sign (to rank candidates by it).
    """
    try:
        gl = tuple(check_gains(params, gains).tolist())
    except GainError:
        return -math.inf
    sc = scale_continuous(params, error_matrix(params, gl))
    g = abs(params.gamma)
    if dt is None:
        if not mu < -sc.spectral_abscissa():
            return -math.inf
        fam = continuous_family(sc.Ahat, sc.w)
        a, b = min(0.0, params.beta - g), max(0.0, params.beta + g)
        enough = (lambda inv: 1.0 - v * inv <= 0) if sign_only else None
        return 1.0 - v * fam.inverse_envelope(a, b, mu, enough=enough)
    sp = prepare_sampled(params, discrete_gains(params, gl, dt), dt)
    fam = sampled_family(sp.Ad1, sp.b, sp.s, sp.w, dt)
    if not mu < fam.decay_cap():
        return -math.inf
    x_lo, x_hi = rho_exponents(params, v, dt)
    if not x_hi < 300.0:
        return -math.inf
    enough = (lambda q: q <= 0) if sign_only else None
    return fam.min_q(-math.expm1(x_hi) / dt, -math.expm1(x_lo) / dt, mu, enough=enough)


class _Searched:
    """Stand-in solution for gains found by the exact pole search."""

    ok = True
    status = "exact search"
    solver = "exact search"
    attempts = ()


def _search(
    params: BoucWenParams,
    udot_max: float,
    decay: float,
    R: float,
    dt: float | None,
    allow_unbounded: bool,
    first: _Attempt,
) -> SynthesisResult | None:
    """Before answering "infeasible": the exact criterion over pole patterns in the region.

    The patterns form a fixed set filtered by the region, so a larger region
    searches a superset: if the search finds gains for a radius it finds them
    for every larger one.
    """
    inside = [c for c in _candidates(params, dt) if c.radius < R * (1 - 1e-12)]
    scored = sorted(
        ((_exact_score(params, c.gains, udot_max, decay, dt), i) for i, c in enumerate(inside)),
        reverse=True,
    )
    tier = "sector" if dt is None else "sampled"
    for score, i in scored[:3]:
        if not score > 0:
            break
        c = inside[i]
        K = None if dt is None else tuple(float(x) for x in discrete_gains(params, c.gains, dt))
        res = _finish(
            params,
            _Attempt(True, _Searched(), None),
            c.gains,
            K,
            tier,
            udot_max,
            decay,
            R,
            dt,
            allow_unbounded,
        )
        if res.feasible:
            return res
    return None


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
    rejected: str = "",
) -> SynthesisResult:
    """Name the binding requirement of a request for which no gains were found.

    The numbers come from the exact criterion over the search's pole patterns
    inside the region (and, for the pole radius, outside it).
    """
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
    cands = _candidates(params, dt)
    inside = [c for c in cands if c.radius < R * (1 - 1e-12)]
    if any(_exact_score(params, c.gains, udot_max, decay, dt) > 0 for c in inside):
        # gains exist by the exact criterion, but none passed re-certification
        solved = first.sol.ok or isinstance(first.sol, _NoSolve)
        return SynthesisResult(
            binding="verification" if solved else "solver",
            reason=(
                f"the exact criterion admits gains within pole radius {R:g} rad/s at "
                f"|u'| <= {udot_max:g} V/s, but none passed re-certification (the {tier} "
                f"synthesis LMI: {'; '.join(first.sol.attempts) or first.sol.status}); no "
                "gains are certified"
            ),
            max_decay=None,
            max_udot=None,
            **common,
        )
    if not first.sol.ok:
        lmi_note = f"; the synthesis LMI was not solved ({first.sol.status})"
    elif rejected:
        lmi_note = f"; the LMI design was rejected: {rejected}"
    else:
        lmi_note = f"; the synthesis LMI has no strictly feasible point (t = {first.t:.3g})"
    where = (
        f"within pole radius {R:g} rad/s at |u'| <= {udot_max:g} V/s ({tier} tier; "
        f"{len(inside)} pole patterns searched)"
    )
    if decay > 0:
        at_zero = [c for c in inside if _exact_score(params, c.gains, udot_max, 0.0, dt) > 0]
        lmi_zero = attempt(udot_max, 0.0, True).ok
        if at_zero or lmi_zero:
            best = 0.0
            if lmi_zero:  # the LMI's own answer, as a lower bound
                best = largest_decay(lambda m: attempt(udot_max, m, True).ok, decay)
            at_zero.sort(key=lambda c: float(np.max(c.poles.real)))
            for c in at_zero[:BEST_OF]:
                cap = decay
                best = max(
                    best,
                    largest_decay(
                        lambda m, g=c.gains: _exact_score(params, g, udot_max, m, dt) > 0, cap
                    ),
                )
            return SynthesisResult(
                binding="decay",
                reason=(
                    f"decay {decay:g} 1/s is not reachable {where}; the largest decay found "
                    f"there is {best:.4g} 1/s" + lmi_note
                ),
                max_decay=best,
                max_udot=None,
                **common,
            )
    outside = sorted(
        (c for c in cands if c.radius >= R * (1 - 1e-12) and math.isfinite(c.radius)),
        key=lambda c: c.radius,
    )
    for c in outside:
        if _exact_score(params, c.gains, udot_max, decay, dt) > 0:
            return SynthesisResult(
                binding="pole_radius",
                reason=(
                    f"no gains found that certify decay {decay:g} 1/s {where}; gains with "
                    f"poles within {c.radius:.4g} rad/s do, so raise the pole radius" + lmi_note
                ),
                max_decay=None,
                max_udot=_best_envelope(params, inside, decay, dt),
                **common,
            )
    best = _best_envelope(params, inside, decay, dt)
    return SynthesisResult(
        binding="udot_max",
        reason=(
            f"|u'| <= {udot_max:g} V/s with decay {decay:g} 1/s is not certifiable by any gains "
            f"found at the {tier} tier (searched {where} and beyond it); the largest envelope "
            f"found is {best:.4g} V/s" + lmi_note
        ),
        max_decay=None,
        max_udot=best,
        **common,
    )


#: The largest envelope of a "no" is measured on this many of the best-ranked patterns.
BEST_OF = 4


def _best_envelope(
    params: BoucWenParams, cands: list[_Candidate], decay: float, dt: float | None
) -> float:
    """Largest exact envelope (V/s) at ``decay`` over the candidates (bisection in ``v``)."""
    best = 0.0
    c_coef = lipschitz_coefficient(params)
    if c_coef == 0:
        return math.inf
    probe = 1e-3 * K_HAT_CAP * math.sqrt(params.a1) / c_coef
    ranked = sorted(cands, key=lambda c: -_exact_score(params, c.gains, probe, decay, dt, False))
    for c in ranked[:BEST_OF]:
        if _exact_score(params, c.gains, best * (1 + 1e-3) if best > 0 else 1e-300, decay, dt) > 0:
            v, _ = largest_rate(
                lambda v, g=c.gains: _exact_score(params, g, v, decay, dt) > 0,
                max(best, 1.0),
                K_HAT_CAP * math.sqrt(params.a1) / c_coef,
                rtol=1e-3,
            )
            best = max(best, v)
    return best


def _synthesize_continuous(
    params: BoucWenParams,
    udot_max: float,
    decay: float,
    R: float,
    allow_unbounded: bool,
    explain: bool = True,
) -> SynthesisResult:
    from ..certify import lmi

    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    A0h = similar(model_matrix(params), T) / w
    Ch = OUTPUT_ROW * T

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

    def extract(sol: Any) -> tuple[tuple[float, ...], None]:
        lh = _gain_from(sol)
        return tuple(float(x) for x in w * T * lh), None

    return _conclude(
        params,
        attempt,
        extract,
        tier="sector",
        udot_max=udot_max,
        decay=decay,
        R=R,
        dt=None,
        allow_unbounded=allow_unbounded,
        explain=explain,
    )


def _synthesize_sampled(
    params: BoucWenParams,
    udot_max: float,
    decay: float,
    R: float,
    dt: float,
    allow_unbounded: bool,
    explain: bool = True,
) -> SynthesisResult:
    from ..certify import lmi

    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    F = np.array(discretize(params, dt).F)
    Fh = similar(F, T)
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

    def extract(sol: Any) -> tuple[Any, tuple[float, ...]]:
        K = tuple(float(x) for x in T * _gain_from(sol))
        return continuous_equivalent(params, K, dt), K

    return _conclude(
        params,
        attempt,
        extract,
        tier="sampled",
        udot_max=udot_max,
        decay=decay,
        R=R,
        dt=dt,
        allow_unbounded=allow_unbounded,
        explain=explain,
    )


def _gain_from(sol: Any) -> np.ndarray:
    """The scaled gain ``P^-1 Y`` of a synthesis LMI's solution."""
    P = np.asarray(sol["P"])
    return np.linalg.solve((P + P.T) / 2, np.asarray(sol["Y"]).ravel())


def _conclude(
    params: BoucWenParams,
    attempt: Callable[..., _Attempt],
    extract: Callable[[Any], tuple[Any, Any]],
    *,
    tier: str,
    udot_max: float,
    decay: float,
    R: float,
    dt: float | None,
    allow_unbounded: bool,
    explain: bool = True,
) -> SynthesisResult:
    """The one ending of both syntheses: refine a feasible LMI design and verify its gains
    outside the solver; otherwise search the pole region with the exact criterion; otherwise
    name the binding requirement (:func:`_diagnose`; with ``explain`` only)."""
    first = attempt(udot_max, decay, True)
    rejected = ""
    if first.ok:
        design = _refine(first, lambda t_min: attempt(udot_max, decay, True, t_min))
        gains, K = extract(design.sol)
        res = _finish(params, first, gains, K, tier, udot_max, decay, R, dt, allow_unbounded)
        if res.feasible:
            return res
        rejected = res.reason
    found = _search(params, udot_max, decay, R, dt, allow_unbounded, first)
    if found is not None:
        return found
    if not explain:
        return _unexplained(params, tier, udot_max, decay, R, dt, first, rejected)
    return _diagnose(
        params,
        attempt,
        tier=tier,
        udot_max=udot_max,
        decay=decay,
        R=R,
        dt=dt,
        first=first,
        rejected=rejected,
    )


def _unexplained(
    params: BoucWenParams,
    tier: str,
    udot_max: float,
    decay: float,
    R: float,
    dt: float | None,
    first: _Attempt,
    rejected: str,
) -> SynthesisResult:
    """A "no" whose binding requirement was not looked for (``explain=False``)."""
    note = f"; the LMI design was rejected: {rejected}" if rejected else ""
    return SynthesisResult(
        feasible=False,
        tier=tier,
        gains=None,
        discrete_gains=None,
        udot_max=udot_max,
        decay=decay,
        pole_radius=R,
        dt=dt,
        binding="unexplained",
        reason=(
            f"no {tier} gains found within pole radius {R:g} rad/s at |u'| <= {udot_max:g} V/s "
            f"with decay {decay:g} 1/s (LMI and pole-pattern search; the binding requirement "
            f"was not looked for){note}"
        ),
        max_decay=None,
        max_udot=None,
        margin=first.t,
        solver=first.sol.solver,
        status=first.sol.status,
        report=None,
        params=params,
    )


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
    disk = _pole_disk(params, gains, K, R, dt)
    if holds and not disk.passed:
        holds = False
        problem = (
            f"its poles leave the requested region: {disk.name} is {disk.value:.6g} "
            f"(limit {disk.limit:.6g})"
        )
    if holds:
        what = f"gains l = ({', '.join(f'{g:.6g}' for g in gains)})" if gains else "discrete gains"
        reason = (
            f"{what} certified by the {tier} tier for |u'| <= {udot_max:g} V/s with decay "
            f">= {decay:g} 1/s, poles within {R:g} rad/s"
        )
        if tier == "sampled" and gains is None:
            reason += "; the discrete poles have no exact continuous equivalent"
        reason += f" (checked: {disk.name} = {disk.value:.6g} < {disk.limit:.6g})"
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
        pole_check=disk,
    )
