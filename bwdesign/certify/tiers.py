"""Certified observer gains: four certificate tiers and LMI gain synthesis.

The observer error ``eps = x_hat - x`` of the hysteresis observer (paper eq. 3)
obeys (docs/design.md, section "Error dynamics")::

    eps' = A eps + e3 phi~,   A = A0 - l C,   C = e1',
    A0 = [[0, 1, 0], [-a1, -a2, -a1], [0, 0, 0]],
    phi~ = -k(t) eps3,  k in [min(0, (beta - |gamma|) v), max(0, (beta + |gamma|) v)]

for ``|u'| <= v`` (``v = udot_max``, V/s). The tiers, weakest first:

``theorem1``
    The paper's argument with the sign corrected: ``A'P + PA <= -q I`` and
    ``|phi~| <= L ||eps||`` with ``L = (|beta| + |gamma|) v`` give
    ``V' <= -(q - 2 L ||P||) ||eps||^2``, so it holds iff ``2 L ||P|| < q``.
    Checked for the Lyapunov-equation ``P`` (``q = 1``) and for the least-norm
    ``P`` of the LMI ``A'P + PA <= -I``. Envelope and decay are closed form.
    (The two norms coincide: the Lyapunov operator is monotone, so the
    Lyapunov-equation ``P`` is the least element of that LMI's feasible set;
    the LMI is solved in ``Q = -(A'P + PA) >= I``, where it is well conditioned,
    as a cross-check.)
``lipschitz``
    S-procedure LMI using only ``|phi~| <= L |eps3|``:
    ``[[A'P + PA + 2 mu P + L^2 e3 e3', P e3], [e3' P, -1]] < 0``. By the KYP
    lemma this is ``||e3' (sI - A - mu I)^-1 e3||_inf < 1/L``.
``sector``
    A common quadratic Lyapunov function for ``A - k e3 e3'`` at both ends of
    the ``k`` interval (polytopic LMI); it keeps the sign information
    (``beta >= |gamma|`` makes the hysteresis error dissipative).
``sampled`` (when ``dt`` is given)
    The observer that runs at sample time ``dt`` in predict/update form has
    posterior error ``eps_{k+1} = (I - K C) F diag(1, 1, rho_k) eps_k`` with
    ``F = expm(A0 dt)`` and ``rho_k`` the slope of the exact hysteresis jump
    map, ``rho in [min(1, exp(-(beta + |gamma|) v dt)),
    max(1, exp(-(beta - |gamma|) v dt))]``. The tier is the polytopic discrete
    LMI ``A_d' P A_d <= r^2 P`` over the two ends; decay ``mu = -ln(r)/dt``.
    Continuous gains are mapped to ``K`` by pole matching with the observers'
    own :func:`bwdesign.observers.discrete_gains`, so the tier certifies exactly
    the gain the sampled :class:`~bwdesign.HysteresisObserver` runs.

Envelopes and decay rates (``lipschitz``, ``sector``, ``sampled``) come from an
exact condition: each tier's perturbation is rank one, so a common quadratic
Lyapunov function exists exactly when the circle criterion holds (lossless
S-procedure, KYP), and :mod:`.frequency` evaluates that condition (continuous, or
discrete in delta form) on a pole-adapted frequency grid refined by Brent. That
evaluation is an estimate in double precision; the stated ``max_udot`` (the
envelope at the requested decay) and ``decay_rate`` (the largest decay at
``udot_max``, ``None`` when the tier does not hold) are the largest values at most
1e-6 below it at which a Riccati Lyapunov matrix passed the outside check, so never
above the exact ones; none when no value down to half the estimate passes
(``details.envelope_undecided``, near-marginal poles; see :mod:`.verified`).
``inf`` means every rate, and is stated only when verified there;
``max_udot_capped`` marks a rate verified at the search limit instead.

The verdict ``holds`` needs a Lyapunov matrix at ``udot_max`` and the requested
decay that passed the outside check: first the stabilising solution of the
tier's KYP Riccati equation (no solver), then the LMI (Clarabel, SCS), then the
matrix of a weaker tier (``theorem1``'s ``P`` rescaled is a lipschitz
certificate, the lipschitz ``P`` a sector one), so among the continuous tiers a
stronger tier never certifies less than a weaker one. ``sampled`` is a
different (discrete) system and is not ordered against them.

Numerics: everything is solved in scaled coordinates (``x2`` scaled by
``w0 = sqrt(a1)``, time by ``w0``, then diagonal balancing), because ``a1``
spans 1e3..1e9; the sampled tier in delta form ``(A_d - I)/dt``, formed without
cancellation, so it stays well conditioned as ``dt -> 0``. The matrices are
mapped back, and a tier says ``holds: true`` only after ``P > 0`` and every LMI
block has been re-checked in the original coordinates with
``numpy.linalg.eigvalsh`` (see :class:`Margin`); the sampled blocks are checked
divided by ``dt`` (delta form).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy.linalg import solve_continuous_lyapunov

from ..errors import InputError
from ..memo import Memo
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_sample_time
from ..model.uncertainty import UncertaintyBox
from ..observers.gains import as_gains, check_gains, discrete_gains, error_matrix
from ..validate import DECAY, UDOT_MAX, real
from .checks import (
    Check,
    Scaled,
    check_lipschitz,
    check_sampled,
    check_sector,
    continuous_error,
    lipschitz_candidates,
    lipschitz_coefficient,
    posdef,
    prepare_sampled,
    rho_exponents,
    rho_interval,
    scale_continuous,
    sector_interval,
    verify_lipschitz,
    verify_sector,
)
from .frequency import continuous_family, sampled_family
from .results import (
    BISECT_RTOL,
    TIERS,
    UNIT_ROUNDOFF,
    CertificateReport,
    Margin,
    TierCertificate,
    frozen_array,
)
from .robust_observer import certify_robust_observer
from .verified import (
    UNDECIDABLE,
    Claims,
    lipschitz_claims,
    sampled_claims,
    sector_claims,
    undecided_reason,
    unverified_reason,
)

__all__ = ["certify", "certify_discrete"]


# -- bisections ---------------------------------------------------------------------


def largest_rate(
    pred: Callable[[float], bool], start: float, cap: float, rtol: float = BISECT_RTOL
) -> tuple[float, bool]:
    """Largest ``v`` in ``(0, cap]`` with ``pred(v)`` (monotone), to ``rtol``.

    Returns ``(v, capped)``; ``(0, False)`` when nothing down to ``1e-12 cap`` holds.
    """
    if not math.isfinite(cap):
        cap = start * 1e12
    x = min(start, cap)
    if pred(x):
        lo = x
        while True:
            if lo >= cap:
                return cap, True
            nxt = min(lo * 4.0, cap)
            if pred(nxt):
                lo = nxt
            else:
                hi = nxt
                break
    else:
        hi = x
        floor = cap * 1e-12
        while True:
            nxt = hi / 4.0
            if nxt < floor:
                return 0.0, False
            if pred(nxt):
                lo = nxt
                break
            hi = nxt
    while hi / lo > 1.0 + rtol:
        mid = math.sqrt(lo * hi)
        if pred(mid):
            lo = mid
        else:
            hi = mid
    return lo, False


def largest_decay(pred: Callable[[float], bool], cap: float, rtol: float = BISECT_RTOL) -> float:
    """Largest ``mu`` in ``[0, cap)`` with ``pred(mu)``, to ``rtol`` (0 if none)."""
    if not (cap > 0 and math.isfinite(cap)) or not pred(0.0):
        return 0.0
    hi = cap
    x = cap / 2.0
    floor = cap * 1e-9
    while not pred(x):
        hi = x
        x /= 4.0
        if x < floor:
            return 0.0
    lo = x
    while hi / lo > 1.0 + rtol:
        mid = math.sqrt(lo * hi)
        if pred(mid):
            lo = mid
        else:
            hi = mid
    return lo


def _stated_envelope(envelope: float, decay: float, claims: Claims) -> tuple[float | None, bool]:
    """``(stated, capped)``: the largest verified rate below the estimate ``envelope``.

    ``inf`` only when verified at ``inf``; from an ``inf`` estimate that is not, a rate
    verified below the tier's search cap (``capped``). ``None``: nothing verified.
    """
    if math.isinf(envelope):
        if claims.ok(math.inf, decay):
            return math.inf, False
        stated = claims.stated(claims.cap, 0.0, None, decay)
        return stated, stated is not None
    return claims.stated(envelope, 0.0, None, decay), False


def _exact_tier(
    name: str,
    *,
    udot_max: float,
    decay: float,
    envelope: float,
    check: Callable[[], Check],
    candidates: Sequence[tuple[str, Callable[[], Check]]],
    decay_rate: Callable[[], float],
    details: dict[str, Any],
    claims: Claims,
) -> TierCertificate:
    """A tier whose envelope comes from the frequency domain and whose verdict is a checked P.

    ``holds`` needs a Lyapunov matrix that passed the outside check at
    ``udot_max`` and ``decay``: the stabilising solution of the tier's KYP Riccati
    equation (the exact solution of the criterion, ``claims``), the LMI's, or one
    of the ``candidates`` (matrices of weaker tiers, which are certificates for this
    tier too). The LMI is solved only when the criterion says a certificate exists.
    ``envelope`` (the frequency-domain estimate) is never stated itself: the stated
    ``max_udot`` and ``decay_rate`` are rates at which a Riccati matrix passed the
    outside check (:mod:`.verified`); none is tried when the poles are too
    ill-conditioned for double precision (``cond u > UNDECIDABLE``).
    """
    cond, damping = claims.conditioning(decay)
    hopeless = cond * UNIT_ROUNDOFF > UNDECIDABLE  # no P can pass the outside check: not tried
    if hopeless:
        claims = claims.without_riccati()
    exact_ok = udot_max < envelope
    main: Check | None = claims.first(udot_max, decay) if exact_ok else None
    source = "kyp" if main is not None else ""
    if main is None and exact_ok and not hopeless:
        main, source = check(), "lmi"
    if main is None or not main.ok:
        for label, cand in candidates:
            c = cand()
            if c.ok:
                main, source = c, label
                break
    stated, capped = _stated_envelope(envelope, decay, claims)
    holds = main is not None and main.ok
    if not holds and stated is not None and stated > udot_max:
        # a certificate at a larger rate is one at udot_max (the rate intervals are nested)
        wider = claims.first(stated, decay)
        again = None if wider is None else claims.check(wider.P, udot_max, decay)
        if again is not None and again.ok:
            main, source, holds = again, "kyp", True
    undecided = envelope > 0 and stated is None
    details = {
        **details,
        "envelope_estimate": envelope,
        "envelope_conditioning": cond,
        "pole_damping": damping,
        "envelope_undecided": undecided,
        "P_source": source if holds else None,
    }
    if main is not None and main.t is not None:
        details["lmi_margin"] = main.t
    why = undecided_reason(cond, decay) if undecided else ""
    if holds:
        status = {
            "lmi": "certified",
            "kyp": "certified (P from the KYP Riccati equation)",
        }.get(source, f"certified (P of the {source} tier)")
        est = max(decay, decay_rate())
        rate = claims.stated(est, decay, udot_max, None) or decay
        if undecided:
            status += f"; no envelope above |u'| <= {udot_max:g} V/s is stated: {why}"
    elif not exact_ok:
        rate = None
        status = (
            f"not certified: |u'| <= {udot_max:g} V/s is above this tier's envelope at decay "
            f"{decay:g} 1/s" + (f" (certified up to {stated:.6g} V/s)" if stated else "")
        )
        status += f"; {why}" if undecided else ""
        best_est = decay_rate() if decay > 0 else 0.0
        best = claims.stated(best_est, 0.0, udot_max, None)
        if best is not None:
            details["largest_decay"] = best
            status += f" (at this rate the largest certifiable decay is {best:.4g} 1/s)"
    else:
        rate = None
        ratio = udot_max / envelope
        status = (
            f"{main.status if main is not None else 'not certified'} (the criterion, "
            f"evaluated in double precision, holds: udot_max / envelope estimate = {ratio:.6g}; "
            + (
                why
                if hopeless
                else "no Lyapunov matrix, the Riccati ones included, passed the outside check: "
                + unverified_reason(ratio, damping)
                + (f"; {why}" if undecided else "")
            )
            + ")"
        )
    max_udot = max(stated or 0.0, udot_max) if holds else stated or 0.0
    return TierCertificate(
        name=name,
        holds=holds,
        udot_max=udot_max,
        decay=decay,
        max_udot=max_udot,
        max_udot_capped=capped and max_udot == stated,
        decay_rate=rate,
        P=main.P if holds else None,
        margins=main.margins if main is not None else (),
        solver=main.solver if main is not None else "",
        status=status,
        details=dict(details),
    )


# -- the tiers ----------------------------------------------------------------------


def _theorem1(
    params: BoucWenParams, sc: Scaled, udot_max: float, decay: float, prev: dict
) -> TierCertificate:
    from . import lmi

    c = lipschitz_coefficient(params)
    L = c * udot_max
    A = sc.A

    # Lyapunov equation A'P + PA = -Q in scaled form: Ahat'X + X Ahat = -S'QS,
    # P = S^-T X S^-1 / w.
    def lyap(Qm: np.ndarray) -> np.ndarray:
        rhs = sc.s[:, None] * Qm * sc.s[None, :]
        scale = float(np.abs(rhs).max())
        with warnings.catch_warnings():  # near-marginal poles: scipy perturbs and warns;
            warnings.simplefilter("ignore", RuntimeWarning)  # the outside check judges P
            X = solve_continuous_lyapunov(sc.Ahat.T, -rhs / scale)
        return scale * ((X + X.T) / 2) / np.outer(sc.s, sc.s) / sc.w

    P_lyap = lyap(np.eye(3))
    candidates: list[tuple[str, np.ndarray, str]] = [("lyapunov", P_lyap, "scipy")]
    # least-norm P over A'P + PA <= -I, as an LMI in Q = -(A'P + PA) >= I
    nL = float(np.linalg.eigvalsh(P_lyap).max())
    basis = {}
    for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
        E = np.zeros((3, 3))
        E[i, j] = E[j, i] = 1.0
        basis[(i, j)] = lyap(E)
    sol = lmi.least_norm_lyapunov({k: v / nL for k, v in basis.items()})
    lmi_status = sol.status
    if sol.ok:
        Qs = np.asarray(sol["Q"])
        P_lmi = sum(Qs[i, j] * B for (i, j), B in basis.items())
        candidates.append(("lmi", (P_lmi + P_lmi.T) / 2, sol.solver))

    results = []
    for label, P, solver in candidates:
        pos = posdef("P > 0", P)
        M = A.T @ P + P @ A
        err = float(np.linalg.norm(continuous_error(A, P, 0.0), "fro"))
        q = -(float(np.linalg.eigvalsh((M + M.T) / 2).max()) + err)
        nP = float(np.linalg.eigvalsh(P).max()) * (1 + 8 * UNIT_ROUNDOFF)
        ok_P = pos.passed and q > 0 and nP > 0
        results.append((label, P, solver, pos, q, nP, ok_P))

    details: dict[str, Any] = {"L": L, "lmi_status": lmi_status}
    for label, _, _, _, q, nP, _ in results:
        details[f"norm_P_{label}"] = nP
        details[f"q_{label}"] = q
        details[f"two_L_norm_P_{label}"] = 2 * L * nP
    details["two_L_norm_P"] = details["two_L_norm_P_lyapunov"]

    usable = [r for r in results if r[6]]
    if not usable:
        return TierCertificate(
            name="theorem1",
            holds=False,
            udot_max=udot_max,
            decay=decay,
            max_udot=0.0,
            max_udot_capped=False,
            decay_rate=None,
            P=None,
            margins=tuple(r[3] for r in results),
            solver="scipy",
            status="not certified: no Lyapunov matrix passed the outside check",
            details=dict(details),
        )
    # best candidate: the one with the largest envelope q / (2 c ||P||)
    best = max(usable, key=lambda r: r[4] / r[5])
    label, P, solver, pos, q, nP, _ = best
    rate = max(0.0, (q - 2 * L * nP) / (2 * nP))
    max_udot = max(0.0, (q - 2 * decay * nP) / (2 * c * nP)) if c > 0 else math.inf
    shortfall = 2 * L * nP / q
    details["P_used"] = label
    details["shortfall"] = shortfall
    margins = (pos, Margin("2 L ||P|| < q", 2 * L * nP, q))
    holds = margins[1].passed and rate >= decay
    if holds:
        status = "certified"
    elif not margins[1].passed:
        status = (
            f"not certified: 2 L ||P|| / q = {shortfall:.4g} >= 1 "
            f"(Theorem 1 falls short by this factor)"
        )
    else:
        status = f"not certified: decay {rate:.4g} 1/s < requested {decay:g} 1/s"
    return TierCertificate(
        name="theorem1",
        holds=holds,
        udot_max=udot_max,
        decay=decay,
        max_udot=max_udot,
        max_udot_capped=False,
        decay_rate=rate if holds else None,
        P=frozen_array(P) if holds else None,
        margins=margins,
        solver=solver,
        status=status,
        details=dict(details),
    )


def _circle_envelope(
    fam: Any, lo: float, hi: float, mu: float, alpha0: float, below: float | None = None
) -> float:
    """Exact envelope (V/s) of the sector ``[lo v, hi v]`` at decay ``mu`` (circle criterion).

    ``below``: only ``below < envelope`` is asked; the frequency search stops once it
    is decided false (the value returned is then an upper bound of the envelope that
    answers the question the same way).
    """
    if not mu < alpha0:
        return 0.0
    enough = None if below is None else (lambda inv: inv > 0 and not below < 1.0 / inv)
    inv = fam.inverse_envelope(lo, hi, mu, enough=enough)
    return math.inf if inv <= 0 else 1.0 / inv


def _continuous_exact(
    name: str,
    sc: Scaled,
    udot_max: float,
    decay: float,
    lo: float,
    hi: float,
    check: Callable[[], Check],
    candidates: Sequence[tuple[str, Callable[[], Check]]],
    details: dict[str, Any],
    claims: Claims,
) -> TierCertificate:
    fam = continuous_family(sc.Ahat, sc.w)
    alpha0 = -sc.spectral_abscissa()

    def rate() -> float:
        return fam.largest_decay(
            lambda m: udot_max < _circle_envelope(fam, lo, hi, m, alpha0, below=udot_max)
        )

    return _exact_tier(
        name,
        udot_max=udot_max,
        decay=decay,
        envelope=_circle_envelope(fam, lo, hi, decay, alpha0),
        check=check,
        candidates=candidates,
        decay_rate=rate,
        details=details,
        claims=claims,
    )


def _lipschitz(
    params: BoucWenParams, sc: Scaled, udot_max: float, decay: float, prev: dict
) -> TierCertificate:
    c = lipschitz_coefficient(params)
    L = c * udot_max
    cands = []
    th = prev.get("theorem1")
    if th is not None and th.holds:
        for P in lipschitz_candidates(np.asarray(th.P), L):
            cands.append(
                ("theorem1", lambda P=P: verify_lipschitz(sc, L, decay, P, th.solver, None))
            )
    return _continuous_exact(
        "lipschitz",
        sc,
        udot_max,
        decay,
        -c,
        c,
        lambda: check_lipschitz(sc, L, decay),
        cands,
        {"L": L},
        lipschitz_claims(params, sc),
    )


def _sector(
    params: BoucWenParams, sc: Scaled, udot_max: float, decay: float, prev: dict
) -> TierCertificate:
    k_lo, k_hi = sector_interval(params, udot_max)
    g = abs(params.gamma)
    cands = []
    for name in ("lipschitz", "theorem1"):
        cert = prev.get(name)
        if cert is not None and cert.holds:
            Pc = np.asarray(cert.P)
            cands.append(
                (
                    name,
                    lambda P=Pc, s=cert.solver: verify_sector(sc, k_lo, k_hi, decay, P, s, None),
                )
            )
    return _continuous_exact(
        "sector",
        sc,
        udot_max,
        decay,
        min(0.0, params.beta - g),
        max(0.0, params.beta + g),
        lambda: check_sector(sc, k_lo, k_hi, decay),
        cands,
        {"k_interval": [k_lo, k_hi]},
        sector_claims(params, sc),
    )


def _sampled(
    params: BoucWenParams, K: np.ndarray, udot_max: float, decay: float, dt: float
) -> TierCertificate:
    sp = prepare_sampled(params, K, dt)
    c = lipschitz_coefficient(params)
    fam = sampled_family(sp.Ad1, sp.b, sp.s, sp.w, dt)
    cap = fam.decay_cap()

    def kfun(v: float) -> tuple[float, float]:
        x_lo, x_hi = rho_exponents(params, v, dt)
        return -math.expm1(x_hi) / dt, -math.expm1(x_lo) / dt

    def feasible(v: float, m: float) -> bool:
        return m < cap and fam.min_q(*kfun(v), m, enough=lambda q: q <= 0) > 0

    if not decay < cap:
        env = 0.0
    elif c == 0:
        env = math.inf
    else:
        env = fam.envelope_by_bisection(kfun, decay, 300.0 / (c * dt))
    x_lo, x_hi = rho_exponents(params, udot_max, dt)
    rho_lo, rho_hi = rho_interval(params, udot_max, dt)
    return _exact_tier(
        "sampled",
        udot_max=udot_max,
        decay=decay,
        envelope=env,
        check=lambda: check_sampled(sp, x_lo, x_hi, decay),
        candidates=(),
        decay_rate=lambda: fam.largest_decay(lambda m: feasible(udot_max, m)),
        details={
            "dt": dt,
            "rho_interval": [rho_lo, rho_hi],
            "discrete_gains": [float(x) for x in K],
            "r": math.exp(-decay * dt),
            "nominal_decay": cap,
        },
        claims=sampled_claims(params, sp),
    )


_CONTINUOUS_TIERS = {"theorem1": _theorem1, "lipschitz": _lipschitz, "sector": _sector}


# -- public entry points ---------------------------------------------------------------


def certify(
    params: BoucWenParams,
    gains: Sequence[float],
    *,
    udot_max: float,
    decay: float = 0.0,
    dt: float | None = None,
    tiers: Sequence[str] | None = None,
    allow_unbounded: bool = False,
    uncertainty: UncertaintyBox | None = None,
    input_range: tuple[float, float] | None = None,
    noise_max: float = 0.0,
) -> CertificateReport:
    """Certify observer gains for an input-rate envelope, tier by tier.

    Parameters
    ----------
    params : BoucWenParams
        The stage.
    gains : sequence of 3 floats
        Continuous observer gains ``(l1, l2, l3)`` (1/s, 1/s^2, 1/s).
    udot_max : float
        Bound on ``|u'|`` (V/s), > 0.
    decay : float
        Required exponential decay rate of the estimation error (1/s), >= 0.
    dt : float, optional
        Sample time (s); adds the ``sampled`` tier for the predict/update
        observer with the pole-matched discrete gain
        :func:`bwdesign.observers.discrete_gains`.
    tiers : sequence of str, optional
        Compute only these tiers (names from :data:`TIERS`); default all
        (``sampled`` only when ``dt`` is given).
    allow_unbounded : bool
        Accept a model outside the bounded Bouc-Wen class.
    uncertainty : UncertaintyBox, optional
        Also certify the sampled observer error over every plant of this box
        (:func:`bwdesign.certify_robust_observer`, the report's ``robust``); needs
        ``dt`` and ``input_range``.
    input_range : (float, float), optional
        ``(u_lo, u_hi)`` (V): the inputs the plant may be driven with (with ``uncertainty``).
    noise_max : float
        Sensor noise bound (length unit) the robust certificate assumes.

    Returns
    -------
    CertificateReport
        One :class:`TierCertificate` per tier (and ``robust``). Solver trouble is a
        status in the report, never an exception.

    Raises
    ------
    GainError
        Malformed gains, or gains violating the paper's Hurwitz conditions (4).
    InputError
        ``udot_max``, ``decay`` or ``dt`` out of range; ``uncertainty`` without ``dt``
        or ``input_range``.
    ParameterError
        ``uncertainty`` with an undetermined (infinite) half-width or a corner that is
        not a valid model (:meth:`UncertaintyBox.check`; a box leaving the bounded
        class is a robust certificate that does not hold).
    UnboundedModelError
        The model is outside the bounded class and ``allow_unbounded`` is False.

    Examples
    --------
    >>> from bwdesign import preset
    >>> rep = certify(preset("paper_experiment"), (8, 64, -512), udot_max=360.9)
    >>> rep.tier("theorem1").holds, rep.tier("sector").holds
    (False, True)
    """
    require_bounded(params, allow_unbounded)
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_MAX)
    decay = real(decay, "decay (1/s)", within=DECAY)
    if dt is not None:
        dt = check_sample_time(params, dt)
    gains = tuple(check_gains(params, gains).tolist())
    if uncertainty is not None:
        _check_robust_request(params, uncertainty, dt, input_range)
    wanted = _wanted_tiers(tiers, dt)
    args = (params, gains, udot_max, decay, dt, wanted, uncertainty, input_range, noise_max)
    return _CERTIFIED.get(args, lambda: _certify(*args))


#: :func:`certify`'s reports kept by their exact (checked) arguments, in this process: a
#: pure function of them, asked again by the report's parts, the design searches and
#: ``export-c``. A copy goes out.
_CERTIFIED: Memo[CertificateReport] = Memo(32)


def _certify(
    params: BoucWenParams,
    gains: tuple[float, float, float],
    udot_max: float,
    decay: float,
    dt: float | None,
    wanted: Any,
    uncertainty: UncertaintyBox | None,
    input_range: tuple[float, float] | None,
    noise_max: float,
) -> CertificateReport:
    """:func:`certify` of checked arguments (``wanted``: the tiers to compute)."""
    sc = scale_continuous(params, error_matrix(params, gains))
    certs = []
    prev: dict[str, TierCertificate] = {}
    for name in TIERS:
        if name in wanted and name != "sampled":
            prev[name] = _CONTINUOUS_TIERS[name](params, sc, udot_max, decay, prev)
            certs.append(prev[name])
    K = None
    if dt is not None:
        K = discrete_gains(params, gains, dt)
        if "sampled" in wanted:
            certs.append(_sampled(params, K, udot_max, decay, dt))
    robust = None
    if uncertainty is not None:
        robust = certify_robust_observer(
            params,
            gains,
            dt=dt,
            uncertainty=uncertainty,
            udot_max=udot_max,
            input_range=input_range,
            noise_max=noise_max,
        )
    return CertificateReport(
        params=params,
        gains=gains,
        udot_max=udot_max,
        decay=decay,
        dt=dt,
        discrete_gains=None if K is None else (float(K[0]), float(K[1]), float(K[2])),
        certificates=tuple(certs),
        robust=robust,
    )


def _check_robust_request(
    params: BoucWenParams,
    uncertainty: Any,
    dt: float | None,
    input_range: tuple[float, float] | None,
) -> None:
    """A robust certificate needs ``dt``, the input range and a box of usable corners."""
    if dt is None or input_range is None:
        raise InputError(
            "a robust certificate over the uncertainty box needs the sample time dt (s) "
            "and the input range (u_lo, u_hi)"
        )
    if not isinstance(uncertainty, UncertaintyBox):
        raise InputError(f"uncertainty must be an UncertaintyBox, got {uncertainty!r}")
    uncertainty.check(params, bounded=False)  # a box leaving the class: "no", not an error


def _wanted_tiers(tiers: Sequence[str] | str | None, dt: float | None) -> tuple[str, ...]:
    """The tiers asked for (default: every tier, ``sampled`` only with ``dt``)."""
    if tiers is None:
        return TIERS if dt is not None else TIERS[:3]
    wanted = tuple(tiers) if not isinstance(tiers, str) else (tiers,)
    unknown = [t for t in wanted if t not in TIERS]
    if unknown:
        raise InputError(f"unknown tier(s) {unknown}; tiers are {', '.join(TIERS)}")
    if "sampled" in wanted and dt is None:
        raise InputError("the sampled tier needs the sample time dt (s)")
    return wanted


def certify_discrete(
    params: BoucWenParams,
    K: Sequence[float],
    *,
    udot_max: float,
    dt: float,
    decay: float = 0.0,
    allow_unbounded: bool = False,
) -> CertificateReport:
    """The ``sampled`` tier alone, for a discrete update gain ``K``.

    Parameters
    ----------
    params : BoucWenParams
    K : sequence of 3 floats
        Discrete update gain of the predict/update observer.
    udot_max : float
        Bound on ``|u'|`` (V/s); per sample ``|du| <= udot_max dt``.
    dt : float
        Sample time (s).
    decay : float
        Required decay rate (1/s).

    Returns
    -------
    CertificateReport
        With ``gains = None`` and one certificate, ``sampled``.
    """
    require_bounded(params, allow_unbounded)
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_MAX)
    decay = real(decay, "decay (1/s)", within=DECAY)
    dt = check_sample_time(params, dt)
    Kv = np.asarray(as_gains(K, "discrete gains K"))
    cert = _sampled(params, Kv, udot_max, decay, dt)
    return CertificateReport(
        params=params,
        gains=None,
        udot_max=udot_max,
        decay=decay,
        dt=dt,
        discrete_gains=(float(Kv[0]), float(Kv[1]), float(Kv[2])),
        certificates=(cert,),
    )
