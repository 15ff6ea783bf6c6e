"""Stated numbers verified at their own claim: envelopes and decay rates of the exact tiers.

The frequency-domain criterion of :mod:`.frequency` is evaluated in double
precision. For well-damped error poles it is accurate to about 1e-9, but for poles
close to the decay line ``Re s = -mu`` (lightly damped pairs, near-marginal gains)
round-off in the error matrix moves the poles by a sizeable fraction of their
distance to that line, and the estimate can sit above the exact envelope. So a tier
never states the estimate itself: it states the largest of
``estimate * (1 - f)``, ``f`` in :data:`BACKOFF`, at which a Lyapunov matrix from the
tier's KYP Riccati equation passes the outside check (:mod:`.checks`, whose round-off
bounds cover the rounding of the error matrix and of the exponential), and that
rate is a certificate, so it is at most the exact envelope. When no rate down to
half the estimate passes, the tier states no envelope and says why, with the
conditioning number of the poles (:func:`continuous_conditioning`,
:func:`delta_conditioning`): the norm of the error matrix over its distance to a
matrix with a pole on the decay line, so that round-off of relative size ``u`` is
``cond u`` of that distance. Decay rates are verified the same way.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import numpy as np

from ..model.params import BoucWenParams
from .checks import (
    Check,
    Sampled,
    Scaled,
    dare_candidates,
    kyp_candidates,
    lipschitz_coefficient,
    rho_exponents,
    sector_interval,
    verify_lipschitz,
    verify_sampled,
    verify_sector,
)
from .frequency import RankOneFamily, continuous_family, sampled_family
from .results import K_HAT_CAP, REL_MARGIN, UNIT_ROUNDOFF

__all__ = [
    "BACKOFF",
    "UNDECIDABLE",
    "verified_below",
    "continuous_conditioning",
    "delta_conditioning",
    "undecided_reason",
    "unverified_reason",
    "Claims",
    "lipschitz_claims",
    "sector_claims",
    "sampled_claims",
]

#: Relative steps below a frequency-domain estimate at which a stated number is tried,
#: in turn; the first rate (or decay) at which a Lyapunov matrix passes is stated.
BACKOFF = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 3e-2, 0.1, 0.3, 0.5)
#: Poles whose round-off (conditioning times the unit round-off) exceeds this fraction of
#: their distance to the decay line are not tried at all: the outside check cannot pass
#: there (calibrated on the audit's near-marginal cases).
UNDECIDABLE = 1e-6


def verified_below(est: float, floor: float, ok: Callable[[float], bool]) -> float | None:
    """The largest ``est * (1 - f)`` (``f`` in :data:`BACKOFF`) above ``floor`` with ``ok``.

    ``None`` when none passes (nothing may then be stated above ``floor``).
    """
    if not (est > floor and math.isfinite(est)):
        return None
    for f in BACKOFF:
        x = est * (1.0 - f)
        if not x > floor:
            return None
        if ok(x):
            return x
    return None


def _conditioning(fam: RankOneFamily, mu: float) -> tuple[float, float]:
    """``(||Ahat|| / r, min_i gap_i / |lambda_i|)``: ``r`` the distance of the scaled
    nominal matrix to one with a pole on the contour (:meth:`RankOneFamily.stability_radius`),
    ``gap_i`` the distance of pole ``i`` to the decay line (delta form: in decay rate)."""
    lam = fam.poles()
    if fam.dt is None:
        gaps = np.abs(lam.real + mu)
    else:
        m2 = fam.dt * (2.0 * lam.real + fam.dt * np.abs(lam) ** 2)  # |z|^2 - 1
        with np.errstate(divide="ignore", invalid="ignore"):
            decay = np.where(m2 > -1.0, -0.5 * np.log1p(np.maximum(m2, -1.0)) / fam.dt, np.inf)
        gaps = np.abs(decay - mu)
    damping = float(np.min(gaps / np.maximum(np.abs(lam), np.finfo(float).tiny)))
    r = fam.stability_radius(mu)
    cond = float(np.linalg.norm(fam.Ahat, 2)) / r if r > 0 else math.inf
    return cond, damping


def continuous_conditioning(sc: Scaled, mu: float) -> tuple[float, float]:
    """Conditioning of the poles against the decay line ``Re s = -mu`` (the matrix norm over
    its distance to a matrix with a pole on that line) and their relative damping (distance
    to that line over ``|lambda|``), continuous tiers."""
    return _conditioning(continuous_family(sc.Ahat, sc.w), mu)


def delta_conditioning(sp: Sampled, mu: float) -> tuple[float, float]:
    """The same for the sampled tier: the delta-form poles against the circle ``|z| = r``."""
    return _conditioning(sampled_family(sp.Ad1, sp.b, sp.s, sp.w, sp.dt), mu)


def undecided_reason(cond: float, mu: float) -> str:
    """Why no envelope is stated, with the conditioning number."""
    return (
        "double precision cannot decide this tier's envelope: no Lyapunov matrix passed the "
        "outside check down to half the frequency-domain estimate; round-off in the error "
        f"matrix is {cond * UNIT_ROUNDOFF:.2g} of its distance to a matrix with a pole on the "
        f"decay line (rate {mu:g} 1/s; conditioning {cond:.3g})"
    )


def unverified_reason(ratio: float, damping: float) -> str:
    """Why no certificate at a rate the criterion accepts (``ratio`` = rate / estimate)."""
    return (
        f"the poles' relative damping to the decay line is {damping:.2g} and the rate is "
        f"{1.0 - ratio:.2g} below the estimate: a certificate's relative margin is about their "
        f"product, against the {REL_MARGIN:g} the outside check requires"
    )


# -- the verifiers -------------------------------------------------------------------


@dataclass(frozen=True)
class Claims:
    """How a tier verifies a rate: its Riccati matrices and its outside check.

    Attributes
    ----------
    candidates : callable
        ``candidates(v, mu)``: Lyapunov matrices from the tier's KYP Riccati equation at
        rate ``v`` (V/s) and decay ``mu`` (1/s), lazily.
    check : callable
        ``check(P, v, mu)``: the tier's outside check of ``P`` there.
    cap : float
        The finite rate (V/s) tried when the estimate is ``inf`` and ``inf`` itself
        cannot be verified; a rate stated from it is marked ``max_udot_capped``.
    conditioning : callable
        ``conditioning(mu)``: ``(conditioning, relative damping)`` of the poles, see
        :func:`continuous_conditioning`.
    """

    candidates: Callable[[float, float], Iterable[np.ndarray]]
    check: Callable[[np.ndarray, float, float], Check]
    cap: float
    conditioning: Callable[[float], tuple[float, float]]

    def first(self, v: float, mu: float) -> Check | None:
        """The first Riccati matrix that passes the check at ``(v, mu)``, or ``None``."""
        for P in self.candidates(v, mu):
            c = self.check(P, v, mu)
            if c.ok:
                return c
        return None

    def ok(self, v: float, mu: float) -> bool:
        return self.first(v, mu) is not None

    def stated(self, est: float, floor: float, v: float | None, mu: float | None) -> float | None:
        """:func:`verified_below` for the rate (``v`` None) or the decay (``mu`` None)."""
        if v is None:
            return verified_below(est, floor, lambda x: self.ok(x, mu))
        return verified_below(est, floor, lambda m: self.ok(v, m))

    def without_riccati(self) -> Claims:
        """The same claims with no Riccati matrix to try (every rate unverified)."""
        return replace(self, candidates=lambda v, mu: ())


def lipschitz_claims(params: BoucWenParams, sc: Scaled) -> Claims:
    c = lipschitz_coefficient(params)

    def cands(v: float, mu: float) -> Iterable[np.ndarray]:
        return kyp_candidates(sc, -c * v, c * v, mu) if math.isfinite(c * v) else ()

    return Claims(
        candidates=cands,
        check=lambda P, v, mu: verify_lipschitz(sc, c * v, mu, P, "scipy", None),
        cap=K_HAT_CAP * sc.w / c if c > 0 else math.inf,
        conditioning=lambda mu: continuous_conditioning(sc, mu),
    )


def sector_claims(params: BoucWenParams, sc: Scaled) -> Claims:
    c = lipschitz_coefficient(params)

    def cands(v: float, mu: float) -> Iterable[np.ndarray]:
        return kyp_candidates(sc, *sector_interval(params, v), mu) if math.isfinite(v) else ()

    def check(P: np.ndarray, v: float, mu: float) -> Check:
        return verify_sector(sc, *sector_interval(params, v), mu, P, "scipy", None)

    return Claims(
        candidates=cands,
        check=check,
        cap=K_HAT_CAP * sc.w / c if c > 0 else math.inf,
        conditioning=lambda mu: continuous_conditioning(sc, mu),
    )


def sampled_claims(params: BoucWenParams, sp: Sampled) -> Claims:
    """Also at ``v = inf`` when ``beta >= |gamma|`` (the jump-map slope then stays in [0, 1])."""
    dt = sp.dt
    c = lipschitz_coefficient(params)

    def ends(v: float) -> tuple[float, float] | None:
        if math.isinf(v):
            return (-math.inf, 0.0) if params.beta >= abs(params.gamma) else None
        x_lo, x_hi = rho_exponents(params, v, dt)
        return (x_lo, x_hi) if x_hi < 700.0 else None

    def cands(v: float, mu: float) -> Iterable[np.ndarray]:
        x = ends(v)
        if x is None:
            return ()
        return dare_candidates(sp, -math.expm1(x[1]) / dt, -math.expm1(x[0]) / dt, mu)

    def check(P: np.ndarray, v: float, mu: float) -> Check:
        x = ends(v)
        if x is None:
            return Check(False, None, (), "", "not certified: the rho interval is unbounded")
        return verify_sampled(sp, x[0], x[1], mu, P, "scipy", None)

    return Claims(
        candidates=cands,
        check=check,
        cap=300.0 / (c * dt) if c > 0 else math.inf,
        conditioning=lambda mu: delta_conditioning(sp, mu),
    )
