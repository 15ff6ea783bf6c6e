"""Seeded audit of ``certify`` and ``synthesize`` against an independent exact check.

Run with ``make audit`` (full campaign, results in ``reports/audit/``) or
``python analysis/certify_audit.py --cases 40 --synth 6 --out DIR`` (a subset).

The exact check is written here, independently of :mod:`bwdesign.certify.frequency`,
in mpmath (``DPS`` digits):

- continuous tiers: the circle-criterion polynomial ``|D|^2 + v S Re(N conj D) + v^2 P |N|^2``
  in ``x = omega^2`` built from the characteristic polynomials of the shifted error
  matrix; positivity on ``x >= 0`` from the critical points of the cubic (closed form);
  the envelope by bisection in ``v``;
- sampled tier: ``F = expm(A0 dt)`` in mpmath, the discrete circle criterion on the
  circle ``|z| = r`` as a cubic in ``cos(theta)`` (Chebyshev form), positivity on
  ``[-1, 1]`` from its critical points; nominal Schur stability from ``mpmath.eig``;
- every ``holds`` re-checked: its ``P`` in mpmath (eigenvalues of every LMI block with
  the exact ``F``) and ``udot_max`` below the exact envelope;
- every stated number re-checked at its own value: each tier's ``max_udot`` must satisfy
  the exact criterion at that rate (``theorem1``'s the lipschitz one, which it implies),
  its ``decay_rate`` (and a stated largest decay) the exact criterion at
  ``(udot_max, rate)``; an overstated envelope or decay fails the audit (exit 1), as do
  a false hold and an exception that is not a typed refusal;
- the generator includes lightly damped (damping 1e-9..1e-3), near-marginal
  (1e-14..1e-9) and beyond-double-precision (1e-18..1e-14) error-pole pairs: there the
  package must state a verified number or none (``envelope_undecided``), never the
  double-precision estimate; the exact check adds two digits per decade of damping;
- the pole-matched ``K`` against Ackermann's formula in mpmath (``DPS_K`` digits);
- synthesis: every "feasible" answer checked for each requested property (pole
  region, envelope at the requested decay) with the exact criterion; every
  "infeasible" answer checked by an exact search over random pole sets in the
  region (a found certificate would be a wrong "no").
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path

# One BLAS thread per process, set before numpy loads: every matrix here is 3x3, and BLAS
# threads contending for shared cores made a 3x3 triangular solve take 2 ms instead of
# 12 us (the audit's 1000 cases then run several times slower). Workers are processes.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import mpmath as mp  # noqa: E402
import numpy as np  # noqa: E402

from bwdesign import BoucWenParams, GainError, certify, synthesize  # noqa: E402
from bwdesign.observers.gains import discrete_gains  # noqa: E402

DPS = 50
DPS_K = 80
#: A "miss" is a case with udot_max below (1 - MISS_MARGIN) times the exact envelope
#: where the tier does not hold.
MISS_MARGIN = 1e-6
#: Envelopes agree when within this relative error of the exact one.
ENVELOPE_RTOL = 0.01
PATTERNS = (
    "typical",
    "slow",
    "fast",
    "spread",
    "clustered",
    "lightly_damped",
    "near_marginal",
    "beyond_double",
)
#: Damping range (log10) of the error-pole pair of the hard patterns.
DAMPING = {
    "lightly_damped": (-9.0, -3.0),
    "near_marginal": (-14.0, -9.0),
    "beyond_double": (-18.0, -14.0),
}
#: The tiers of a certify report, weakest first.
TIERS_AUDITED = ("theorem1", "lipschitz", "sector", "sampled")


# -- random cases -----------------------------------------------------------------------


def random_stage(rng: np.random.Generator) -> BoucWenParams:
    a1 = 10 ** rng.uniform(3, 9)
    zeta = 10 ** rng.uniform(-2, 0)
    beta = 10 ** rng.uniform(-1.5, 0.7)
    gamma = float(rng.choice([-1, 1])) * beta * rng.uniform(0, 1.3)
    return BoucWenParams(
        a1=a1,
        a2=2 * zeta * math.sqrt(a1),
        a3=a1 * 10 ** rng.uniform(-0.5, 0.5),
        alpha=rng.uniform(0.2, 2.0),
        beta=beta,
        gamma=gamma,
        name="audit",
    )


def random_poles(rng: np.random.Generator, w0: float, pattern: str) -> np.ndarray:
    if pattern == "typical":
        m = w0 * 10 ** rng.uniform(-0.5, 0.5)
        mags = m * np.array([1.0, rng.uniform(0.5, 2), rng.uniform(0.5, 2)])
    elif pattern == "slow":
        mags = w0 * 10 ** rng.uniform(-3, -1, 3)
    elif pattern == "fast":
        mags = w0 * 10 ** rng.uniform(1, 2.5, 3)
    elif pattern == "spread":
        mags = w0 * 10 ** np.array([rng.uniform(-3, -1), rng.uniform(-0.5, 0.5), rng.uniform(1, 2)])
    elif pattern in DAMPING:  # a real pole and a pair this close to the imaginary axis
        m = w0 * 10 ** rng.uniform(-1, 1)
        zeta = 10 ** rng.uniform(*DAMPING[pattern])
        pair = m * (-zeta + 1j * math.sqrt(1 - zeta**2))
        return np.array([-m * 10 ** rng.uniform(-0.5, 0.5), pair, np.conj(pair)])
    else:  # clustered
        mags = w0 * 10 ** rng.uniform(-1, 1) * (1 + 0.01 * rng.uniform(-1, 1, 3))
    if rng.uniform() < 0.5:  # one real pole and a damped pair
        zeta = rng.uniform(0.05, 1.0)
        pair = mags[1] * (-zeta + 1j * math.sqrt(1 - zeta**2))
        return np.array([-mags[0], pair, np.conj(pair)])
    return -mags.astype(complex)


def gains_from_poles(p: BoucWenParams, lam: np.ndarray) -> tuple[float, float, float]:
    c = np.real(np.poly(lam))
    l1 = c[1] - p.a2
    l2 = c[2] - p.a1 - l1 * p.a2
    return float(l1), float(l2), float(-c[3] / p.a1)


# -- the exact check (mpmath) -------------------------------------------------------------


def _mpm(a) -> mp.matrix:
    return mp.matrix([[mp.mpf(float(x)) for x in row] for row in np.asarray(a, float)])


def _err_matrix(p: BoucWenParams, g) -> mp.matrix:
    l1, l2, l3 = (mp.mpf(float(x)) for x in g)
    a1, a2 = mp.mpf(p.a1), mp.mpf(p.a2)
    return mp.matrix([[-l1, 1, 0], [-(a1 + l2), -a2, -a1], [-l3, 0, 0]])


def _charpoly3(A: mp.matrix) -> list:
    """Coefficients ``[1, c2, c1, c0]`` of ``det(sI - A)``."""
    tr = A[0, 0] + A[1, 1] + A[2, 2]
    m2 = (
        A[0, 0] * A[1, 1]
        - A[0, 1] * A[1, 0]
        + A[0, 0] * A[2, 2]
        - A[0, 2] * A[2, 0]
        + A[1, 1] * A[2, 2]
        - A[1, 2] * A[2, 1]
    )
    return [mp.mpf(1), -tr, m2, -mp.det(A)]


def _numer(A: mp.matrix, b: mp.matrix) -> list:
    """Coefficients ``[n2, n1, n0]`` of ``e3' adj(sI - A) b`` (Cayley-Hamilton adjugate)."""
    _, c2, c1, _ = _charpoly3(A)
    I3 = mp.eye(3)
    M1 = A + c2 * I3
    M0 = A * A + c2 * A + c1 * I3
    return [b[2], (M1 * b)[2], (M0 * b)[2]]


def _polyval(coeffs: list, x):
    """Horner evaluation, highest power first."""
    out = mp.mpf(0)
    for c in coeffs:
        out = out * x + c
    return out


def _cubic_positive(coeffs: list, lo, hi) -> bool:
    """Is the polynomial (degree <= 3, highest power first) > 0 on ``[lo, hi]`` (hi may be inf)?

    Exact up to the working precision: the minimum over the interval is at an end
    or at a real root of the derivative (a quadratic, solved in closed form).
    """
    while len(coeffs) > 1 and coeffs[0] == 0:
        coeffs = coeffs[1:]
    if _polyval(coeffs, lo) <= 0:
        return False
    if hi == mp.inf:
        if len(coeffs) > 1 and coeffs[0] < 0:
            return False
    elif _polyval(coeffs, hi) <= 0:
        return False
    n = len(coeffs) - 1
    der = [c * (n - k) for k, c in enumerate(coeffs[:-1])]
    while len(der) > 1 and der[0] == 0:
        der = der[1:]
    crit = []
    if len(der) == 2:
        crit = [-der[1] / der[0]]
    elif len(der) == 3:
        a, b, c = der
        disc = b * b - 4 * a * c
        if disc >= 0:
            sq = mp.sqrt(disc)
            q = -(b + (sq if b >= 0 else -sq)) / 2
            crit = [q / a] + ([c / q] if q != 0 else [])
    for x in crit:
        if lo < x and (hi == mp.inf or x < hi) and _polyval(coeffs, x) <= 0:
            return False
    return True


def _bisect(feasible, lo=1e-30, hi=1e30) -> float:
    """Largest v with feasible(v) (monotone), to relative 1e-9; inf if feasible(hi)."""
    if feasible(hi):
        return math.inf
    if not feasible(lo):
        return 0.0
    a, b = math.log(lo), math.log(hi)
    while b - a > 1e-9:
        m = (a + b) / 2
        if feasible(math.exp(m)):
            a = m
        else:
            b = m
    return math.exp(a)


def exact_continuous_envelope(
    p: BoucWenParams, g, lo_rate: float, hi_rate: float, mu: float, at: float | None = None
):
    """Exact envelope (V/s) of the sector ``[lo_rate v, hi_rate v]`` at decay mu.

    With ``at``: only whether ``at`` (V/s) is certifiable (bool).
    """
    with mp.workdps(DPS + _extra_digits(p, g, mu)):
        A = _err_matrix(p, g) + mp.mpf(mu) * mp.eye(3)
        _, d2, d1, d0 = _charpoly3(A)
        if not (d2 > 0 and d0 > 0 and d2 * d1 > d0):
            return False if at is not None else 0.0
        b = mp.matrix([0, 0, 1])
        n2, n1, n0 = _numer(A, b)  # n2 = 1
        # D(jw) = (d0 - d2 x) + j w (d1 - x);  N(jw) = (n0 - n2 x) + j w n1,  x = w^2
        Dr, Di = [-d2, d0], [mp.mpf(-1), d1]
        Nr, Ni = [-n2, n0], [n1]
        D2 = mp.matrix(4, 1)
        poly = _padd(_pmul(Dr, Dr), _pmul([1, 0], _pmul(Di, Di)))
        NN = _padd(_pmul(Nr, Nr), _pmul([1, 0], _pmul(Ni, Ni)))
        ND = _padd(_pmul(Nr, Dr), _pmul([1, 0], _pmul(Ni, Di)))
        del D2
        S = mp.mpf(lo_rate) + mp.mpf(hi_rate)
        P = mp.mpf(lo_rate) * mp.mpf(hi_rate)

        def feasible(v: float) -> bool:
            v = mp.mpf(v)
            q = _padd(poly, _padd(_pscale(ND, v * S), _pscale(NN, v * v * P)))
            return _cubic_positive(q, mp.mpf(0), mp.inf)

        return feasible(at) if at is not None else _bisect(feasible)


def _extra_digits(p: BoucWenParams, g, mu: float) -> int:
    """Two digits per decade of the poles' relative distance to ``Re s = -mu`` beyond 1e-10.

    The circle polynomial's minimum is then a near double root, which cancels about
    twice that many digits.
    """
    with mp.workdps(DPS):
        lam = mp.eig(_err_matrix(p, g))[0]
        rel = min(abs(mp.re(x) + mu) for x in lam) / max(abs(x) for x in lam)
    if rel == 0:
        return 2 * DPS
    return max(0, 2 * int(math.ceil(-float(mp.log10(rel)))) - 20)


def _pmul(a, b):
    out = [mp.mpf(0)] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i + j] += x * y
    return out


def _padd(a, b):
    n = max(len(a), len(b))
    a = [mp.mpf(0)] * (n - len(a)) + list(a)
    b = [mp.mpf(0)] * (n - len(b)) + list(b)
    return [x + y for x, y in zip(a, b, strict=True)]


def _pscale(a, s):
    return [x * s for x in a]


def exact_F(p: BoucWenParams, dt: float) -> mp.matrix:
    A0 = mp.matrix([[0, 1, 0], [-mp.mpf(p.a1), -mp.mpf(p.a2), -mp.mpf(p.a1)], [0, 0, 0]])
    return mp.expm(A0 * mp.mpf(dt))


def exact_K(p: BoucWenParams, g, dt: float) -> np.ndarray:
    with mp.workdps(DPS_K):
        F = exact_F(p, dt)
        lam = mp.eig(_err_matrix(p, g))[0]
        z = [mp.exp(x * mp.mpf(dt)) for x in lam]
        c = [mp.mpf(1), -(z[0] + z[1] + z[2]), z[0] * z[1] + z[0] * z[2] + z[1] * z[2]]
        c.append(-z[0] * z[1] * z[2])
        c = [mp.re(x) for x in c]
        H = F[0, :]
        O = mp.matrix(3, 3)
        row = H
        for i in range(3):
            for j in range(3):
                O[i, j] = row[j]
            row = row * F
        phi = F * F * F + c[1] * F * F + c[2] * F + c[3] * mp.eye(3)
        K = phi * mp.lu_solve(O, mp.matrix([0, 0, 1]))
        return np.array([float(K[i]) for i in range(3)])


def _cheb_poly(c: list) -> list:
    """``sum_m c[m] cos(m theta)`` (m = 0..3) as a polynomial in x = cos(theta), high first."""
    # T0 = 1, T1 = x, T2 = 2x^2 - 1, T3 = 4x^3 - 3x
    c = list(c) + [mp.mpf(0)] * (4 - len(c))
    return [4 * c[3], 2 * c[2], c[1] - 3 * c[3], c[0] - c[2]]


def _trig_re(a: list, b: list) -> list:
    """Re(A(e^{j theta}) conj(B(e^{j theta}))) for real polys (low power first) as cosine series."""
    out = [mp.mpf(0)] * 4
    for k, x in enumerate(a):
        for m, y in enumerate(b):
            out[abs(k - m)] += x * y
    return out


def exact_sampled(p: BoucWenParams, K, dt: float, mu: float, at: float | None = None):
    """Exact envelope (V/s) of the sampled tier for the discrete gain K at decay mu.

    With ``at``: only whether ``at`` (V/s) is certifiable (bool).
    """
    # |D(e^{j theta})|^2 is a product of six factors |e^{j theta} - z_i| ~ |z_i - 1|, so the
    # Chebyshev form cancels about 6 log10(1/|z_i - 1|) digits: add them to the precision.
    with mp.workdps(DPS):
        F = exact_F(p, dt)
        F[2, 0], F[2, 1], F[2, 2] = 0, 0, 1
        Kc = mp.matrix([mp.mpf(float(k)) for k in K])
        Ad = (mp.eye(3) - Kc * mp.matrix([[1, 0, 0]])) * F
        near = min(abs(z - 1) for z in mp.eig(Ad)[0])
    extra = 6 * max(0, int(math.ceil(-math.log10(max(float(near), 1e-300)))))
    with mp.workdps(DPS + extra):
        F = exact_F(p, dt)
        F[2, 0], F[2, 1], F[2, 2] = 0, 0, 1
        Kc = mp.matrix([mp.mpf(float(k)) for k in K])
        C = mp.matrix([[1, 0, 0]])
        Ad = (mp.eye(3) - Kc * C) * F
        r = mp.exp(-mp.mpf(mu) * mp.mpf(dt))
        A = Ad / r
        b = mp.matrix([A[0, 2], A[1, 2], A[2, 2]])
        cp = _charpoly3(A)
        roots = mp.eig(A)[0]
        if max(abs(x) for x in roots) >= 1:
            return False if at is not None else 0.0
        n2, n1, n0 = _numer(A, b)
        Dlow = [cp[3], cp[2], cp[1], cp[0]]
        Nlow = [n0, n1, n2]
        DD = _cheb_poly(_trig_re(Dlow, Dlow))
        ND = _cheb_poly(_trig_re(Nlow, Dlow))
        NN = _cheb_poly(_trig_re(Nlow, Nlow))
        g = abs(p.gamma)

        def feasible(v: float) -> bool:
            w = mp.mpf(v) * mp.mpf(dt)
            x_lo = min(mp.mpf(0), -(mp.mpf(p.beta) + g) * w)
            x_hi = max(mp.mpf(0), -(mp.mpf(p.beta) - g) * w)
            if x_hi > 600:
                return False
            k1 = 1 - mp.exp(x_hi)  # feedback k = 1 - rho on w = (rho - 1) y
            k2 = 1 - mp.exp(x_lo)
            q = _padd(DD, _padd(_pscale(ND, k1 + k2), _pscale(NN, k1 * k2)))
            return _cubic_positive(q, mp.mpf(-1), mp.mpf(1))

        if at is not None:
            return feasible(at)
        return _bisect(feasible, 1e-30, 300.0 / ((abs(p.beta) + g) * dt))


def _mp_negdef(M: mp.matrix) -> bool:
    Ms = (M + M.T) / 2
    return max(mp.eigsy(Ms, eigvals_only=True)) < 0


def exact_P_check(p: BoucWenParams, g, cert, udot_max: float, decay: float, K, dt) -> bool:
    """The tier's P re-checked in mpmath (exact F for the sampled tier)."""
    with mp.workdps(DPS):
        P = _mpm(cert.P)
        if not _mp_negdef(-P):
            return False
        mu = mp.mpf(decay)
        c = abs(p.beta) + abs(p.gamma)
        if cert.name == "sampled":
            F = exact_F(p, dt)
            F[2, 0], F[2, 1], F[2, 2] = 0, 0, 1
            Kc = mp.matrix([mp.mpf(float(k)) for k in K])
            Ad = (mp.eye(3) - Kc * mp.matrix([[1, 0, 0]])) * F
            r2 = mp.exp(-2 * mu * mp.mpf(dt))
            g_ = abs(p.gamma)
            w = mp.mpf(udot_max) * mp.mpf(dt)
            for x in (min(0, -(p.beta + g_) * w), max(0, -(p.beta - g_) * w)):
                R = mp.diag([1, 1, mp.exp(x)])
                Ar = Ad * R
                if not _mp_negdef(Ar.T * P * Ar - r2 * P):
                    return False
            return True
        A = _err_matrix(p, g)
        I3 = mp.eye(3)
        if cert.name == "theorem1":
            M = A.T * P + P * A
            q = -max(mp.eigsy((M + M.T) / 2, eigvals_only=True))
            nP = max(mp.eigsy(P, eigvals_only=True))
            L = mp.mpf(c) * mp.mpf(udot_max)
            return q > 0 and 2 * L * nP + 2 * mu * nP < q
        if cert.name == "lipschitz":
            L = mp.mpf(c) * mp.mpf(udot_max)
            M = mp.zeros(4, 4)
            top = A.T * P + P * A + 2 * mu * P
            top[2, 2] += L * L
            for i in range(3):
                for j in range(3):
                    M[i, j] = top[i, j]
                M[i, 3] = M[3, i] = P[i, 2]
            M[3, 3] = -1
            return _mp_negdef(M)
        g_ = abs(p.gamma)
        for k in (min(0, (p.beta - g_) * udot_max), max(0, (p.beta + g_) * udot_max)):
            Ak = A - mp.mpf(k) * mp.matrix([[0, 0, 0], [0, 0, 0], [0, 0, 1]])
            if not _mp_negdef(Ak.T * P + P * Ak + 2 * mu * P):
                return False
        del I3
        return True


# -- the campaign ---------------------------------------------------------------------------


def exact_hurwitz(p: BoucWenParams, g) -> bool:
    """Is ``A0 - l C`` Hurwitz for the gains as given (Routh-Hurwitz in mpmath)?"""
    with mp.workdps(DPS + _extra_digits(p, g, 0.0)):
        _, d2, d1, d0 = _charpoly3(_err_matrix(p, g))
        return bool(d2 > 0 and d0 > 0 and d2 * d1 > d0)


def _stated_ok(exact_at, stated: float, exact_env: float) -> bool:
    """Is a stated envelope at most the exact one (decided by the exact criterion at it)?"""
    if stated <= 0:
        return True
    if math.isinf(stated):
        return math.isinf(exact_env)
    return bool(exact_at(stated))


def _check_claims(p, g, cert, v: float, decay: float, K, dt) -> dict:
    """The numbers a tier states, each re-checked exactly at its own value."""
    gam = abs(p.gamma)
    c = abs(p.beta) + gam
    sec = (min(0.0, p.beta - gam), max(0.0, p.beta + gam))

    def crit(name: str, rate: float, mu: float) -> bool:
        if name == "sampled":
            return bool(exact_sampled(p, K, dt, mu, at=rate))
        lo, hi = (-c, c) if name in ("lipschitz", "theorem1") else sec
        return bool(exact_continuous_envelope(p, g, lo, hi, mu, at=rate))

    out = {}
    if cert.max_udot > 0 and math.isfinite(cert.max_udot):
        out["envelope_ok"] = crit(cert.name, cert.max_udot, decay)
    elif math.isinf(cert.max_udot):
        out["envelope_ok"] = cert.name == "sampled" and math.isinf(exact_sampled(p, K, dt, decay))
    for key in ("decay_rate", "largest_decay"):
        mu = cert.decay_rate if key == "decay_rate" else cert.details.get(key)
        if mu is not None and mu > decay:
            out[f"{key}_ok"] = crit(cert.name, v, mu)
    return out


def run_case(rng: np.random.Generator, i: int) -> dict:
    p = random_stage(rng)
    pattern = PATTERNS[i % len(PATTERNS)]
    lam = random_poles(rng, math.sqrt(p.a1), pattern)
    g = gains_from_poles(p, lam)
    v = 10 ** rng.uniform(-3, 7)
    dt = 10 ** rng.uniform(-6, -3)
    alpha0 = float(-np.max(lam.real))
    decay = 0.0 if rng.uniform() < 0.7 else alpha0 * rng.uniform(0, 0.5)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        rep = certify(p, g, udot_max=v, decay=decay, dt=dt, allow_unbounded=True)
    except GainError as err:  # a typed refusal: right when the gains are not exactly Hurwitz
        hurwitz = exact_hurwitz(p, g)
        return {
            "case": i,
            "pattern": pattern,
            "refused": f"{type(err).__name__}: {err}",
            "exactly_hurwitz": hurwitz,
        }
    except Exception as err:  # noqa: BLE001 - an exception is a finding, recorded
        return {"case": i, "pattern": pattern, "error": f"{type(err).__name__}: {err}"}
    elapsed = time.perf_counter() - t0
    cpu = time.process_time() - c0
    K = np.asarray(rep.discrete_gains)
    Kx = exact_K(p, g, dt)
    k_err = float(np.max(np.abs(K - Kx) / np.abs(Kx)))
    gam = abs(p.gamma)
    c = abs(p.beta) + gam
    exact = {
        "lipschitz": exact_continuous_envelope(p, g, -c, c, decay),
        "sector": exact_continuous_envelope(
            p, g, min(0.0, p.beta - gam), max(0.0, p.beta + gam), decay
        ),
        "sampled": exact_sampled(p, K, dt, decay),
    }
    tiers = {}
    for cert in rep.certificates:
        row = {
            "holds": cert.holds,
            "max_udot": cert.max_udot,
            "decay_rate": cert.decay_rate,
            "status": cert.status,
            "undecided": bool(cert.details.get("envelope_undecided", False)),
        }
        if cert.name in exact:
            env = exact[cert.name]
            row["exact"] = env
            row["false_hold"] = bool(cert.holds and not v < env * (1 + 1e-9))
            row["miss"] = bool((not cert.holds) and v < env * (1 - MISS_MARGIN))
            if math.isfinite(env) and env > 0:
                row["env_rel_err"] = abs(cert.max_udot - env) / env
            elif env == 0:
                row["env_rel_err"] = 0.0 if cert.max_udot == 0 else math.inf
            else:
                row["env_rel_err"] = 0.0 if math.isinf(cert.max_udot) else math.inf
        claims = _check_claims(p, g, cert, v, decay, K, dt)
        row["overstated"] = not claims.get("envelope_ok", True)
        row["decay_overstated"] = not all(
            claims.get(k, True) for k in ("decay_rate_ok", "largest_decay_ok")
        )
        if cert.holds:
            ok = exact_P_check(p, g, cert, v, decay, K, dt)
            row["P_exact_ok"] = ok
            row["false_hold"] = row.get("false_hold", False) or not ok
        tiers[cert.name] = row
    with mp.workdps(DPS + _extra_digits(p, g, 0.0)):
        ev = mp.eig(_err_matrix(p, g))[0]
        damping = min(float(-mp.re(x) / abs(x)) for x in ev)
    return {
        "case": i,
        "pattern": pattern,
        "a1": p.a1,
        "a2": p.a2,
        "beta": p.beta,
        "gamma": p.gamma,
        "gains": list(g),
        "udot_max": v,
        "decay": decay,
        "dt": dt,
        "damping": damping,
        "lam_dt": float(np.min(np.abs(lam)) * dt),
        "K_rel_err": k_err,
        "time": elapsed,
        "cpu_time": cpu,
        "tiers": tiers,
    }


def _exact_ok_sector(p, g, v, decay) -> bool:
    gam = abs(p.gamma)
    return exact_continuous_envelope(
        p, g, min(0.0, p.beta - gam), max(0.0, p.beta + gam), decay, at=v
    )


def run_synthesis(rng: np.random.Generator, i: int, n_search: int) -> dict:
    p = random_stage(rng)
    w0 = math.sqrt(p.a1)
    sampled = i % 2 == 1
    dt = 10 ** rng.uniform(-6, -3) if sampled else None
    R = w0 * 10 ** rng.uniform(-0.5, 1.5)
    if dt is not None:
        R = min(R, 1.0 / dt)
    v = 10 ** rng.uniform(0, 4)
    decay = 0.0 if rng.uniform() < 0.7 else R * rng.uniform(0.001, 0.05)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        res = synthesize(p, udot_max=v, decay=decay, pole_radius=R, dt=dt, allow_unbounded=True)
    except Exception as err:  # noqa: BLE001 - an exception is a finding, recorded
        return {
            "request": i,
            "error": f"{type(err).__name__}: {err}",
            "feasible": False,
            "time": math.nan,
        }
    elapsed = time.perf_counter() - t0
    cpu = time.process_time() - c0
    row = {
        "request": i,
        "cpu_time": cpu,
        "a1": p.a1,
        "beta": p.beta,
        "gamma": p.gamma,
        "udot_max": v,
        "decay": decay,
        "pole_radius": R,
        "dt": dt,
        "feasible": res.feasible,
        "binding": res.binding,
        "reason": res.reason,
        "time": elapsed,
    }
    if res.feasible:
        # every requested property, independently of the solver
        props = {}
        if dt is None:
            lam = np.linalg.eigvals(
                np.array(
                    [
                        [-res.gains[0], 1, 0],
                        [-(p.a1 + res.gains[1]), -p.a2, -p.a1],
                        [-res.gains[2], 0, 0],
                    ]
                )
            )
            with mp.workdps(DPS):
                ev = mp.eig(_err_matrix(p, res.gains))[0]
                props["pole_radius"] = bool(max(abs(x) for x in ev) < R)
                props["hurwitz_decay"] = bool(max(mp.re(x) for x in ev) < -decay)
            del lam
            props["envelope"] = _exact_ok_sector(p, res.gains, v, decay)
        else:
            with mp.workdps(DPS):
                F = exact_F(p, dt)
                F[2, 0], F[2, 1], F[2, 2] = 0, 0, 1
                Kc = mp.matrix([mp.mpf(float(k)) for k in res.discrete_gains])
                Ad = (mp.eye(3) - Kc * mp.matrix([[1, 0, 0]])) * F
                z = mp.eig(Ad)[0]
                props["pole_radius"] = bool(max(abs(x - 1) for x in z) < -mp.expm1(-R * dt))
                props["schur_decay"] = bool(max(abs(x) for x in z) < mp.exp(-decay * dt))
            props["envelope"] = bool(exact_sampled(p, res.discrete_gains, dt, decay, at=v))
        row["properties"] = props
        row["all_properties_hold"] = all(props.values())
    else:
        # an exact search for gains that the "no" says do not exist
        found = None
        for _ in range(n_search):
            mags = R * 10 ** rng.uniform(-3, 0, 3) * 0.999
            zeta = rng.uniform(0.05, 1.0)
            pair = mags[1] * (-zeta + 1j * math.sqrt(1 - zeta**2))
            lam = np.array([-mags[0], pair, np.conj(pair)])
            if decay > 0 and np.max(lam.real) >= -decay:
                continue
            g = gains_from_poles(p, lam)
            if dt is None:
                if _exact_ok_sector(p, g, v, decay):
                    found = g
                    break
            else:
                z = np.exp(lam * dt)
                if np.max(np.abs(z - 1)) >= -math.expm1(-R * dt):
                    continue
                K = discrete_gains(p, g, dt)
                if exact_sampled(p, K, dt, decay, at=v):
                    found = g
                    break
        row["wrong_infeasible"] = found is not None
        row["counterexample"] = None if found is None else list(found)
    return row


def _q(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(math.ceil(q * len(xs))) - 1)] if xs else math.nan


def summarise(cases: list[dict], synth: list[dict]) -> dict:
    errors = [c for c in cases if "error" in c] + [s for s in synth if "error" in s]
    refused = [c for c in cases if "refused" in c]
    cases = [c for c in cases if "error" not in c and "refused" not in c]
    synth = [s for s in synth if "error" not in s]
    out: dict = {
        "cases": len(cases),
        "synthesis_requests": len(synth),
        "exceptions": len(errors),
        "refused_not_hurwitz": sum(not c["exactly_hurwitz"] for c in refused),
        "refused_hurwitz": sum(c["exactly_hurwitz"] for c in refused),
        "tiers": {},
    }
    for tier in TIERS_AUDITED:
        rows = [c["tiers"][tier] for c in cases if tier in c["tiers"]]
        holds = sum(r["holds"] for r in rows)
        s = {
            "holds": holds,
            "false_holds": sum(r.get("false_hold", False) for r in rows),
            "overstated": sum(r["overstated"] for r in rows),
            "decay_overstated": sum(r["decay_overstated"] for r in rows),
            "undecided": sum(r["undecided"] for r in rows),
        }
        if tier != "theorem1":
            certifiable = [r for r in rows if r["exact"] > 0]
            s["certifiable"] = sum(
                1 for c in cases if c["udot_max"] < c["tiers"][tier]["exact"] * (1 - MISS_MARGIN)
            )
            s["misses"] = sum(r["miss"] for r in rows)
            s["misses_undecided"] = sum(r["miss"] and r["undecided"] for r in rows)
            s["miss_rate"] = s["misses"] / max(1, s["certifiable"])
            stated = [r for r in certifiable if math.isfinite(r["exact"]) and not r["undecided"]]
            good = sum(r["env_rel_err"] <= ENVELOPE_RTOL for r in stated)
            s["envelope_within_1pct"] = good
            s["envelope_stated_finite"] = len(stated)
            s["envelope_within_1pct_fraction"] = good / max(1, len(stated))
            s["envelope_max_rel_err"] = max((r["env_rel_err"] for r in stated), default=0.0)
        out["tiers"][tier] = s
    out["patterns"] = {}
    for pat in PATTERNS:
        rows = [c for c in cases if c["pattern"] == pat]
        out["patterns"][pat] = {
            "cases": len(rows),
            "refused": sum(1 for c in refused if c["pattern"] == pat),
            "overstated": sum(r["overstated"] for c in rows for r in c["tiers"].values()),
            "undecided": sum(r["undecided"] for c in rows for r in c["tiers"].values()),
            "misses": sum(r.get("miss", False) for c in rows for r in c["tiers"].values()),
            "false_holds": sum(
                r.get("false_hold", False) for c in rows for r in c["tiers"].values()
            ),
        }
    out["failures"] = len(errors) + sum(
        t["false_holds"] + t["overstated"] + t["decay_overstated"] for t in out["tiers"].values()
    )
    order = ("theorem1", "lipschitz", "sector")
    out["monotone_violations"] = sum(
        1
        for c in cases
        for a, b in zip(order, order[1:], strict=False)
        if c["tiers"][a]["holds"] and not c["tiers"][b]["holds"]
    )
    out["K_rel_err_max"] = max(c["K_rel_err"] for c in cases)
    out["K_within_1e-9"] = sum(c["K_rel_err"] <= 1e-9 for c in cases)
    for key, label in (("time", "wall"), ("cpu_time", "cpu")):
        t = [c[key] for c in cases]
        out[f"certify_{label}_time_s"] = {
            "median": statistics.median(t),
            "p95": _q(t, 0.95),
            "max": max(t),
        }
        if synth:
            ts = [s[key] for s in synth]
            out[f"synthesis_{label}_time_s"] = {
                "median": statistics.median(ts),
                "p95": _q(ts, 0.95),
                "max": max(ts),
            }
    if synth:
        out["synthesis_feasible"] = sum(s["feasible"] for s in synth)
        out["synthesis_wrong_infeasible"] = sum(s.get("wrong_infeasible", False) for s in synth)
        out["synthesis_feasible_property_failures"] = sum(
            1 for s in synth if s["feasible"] and not s["all_properties_hold"]
        )
        out["synthesis_infeasible_answers"] = [
            {"request": s["request"], "binding": s["binding"], "reason": s["reason"]}
            for s in synth
            if not s["feasible"]
        ]
    return out


def markdown(summary: dict, args: argparse.Namespace, cases: list[dict]) -> str:
    cases = [c for c in cases if "error" not in c and "refused" not in c]
    verdict = "PASSED" if summary["failures"] == 0 else f"FAILED ({summary['failures']} findings)"
    lines = [
        "# Audit of certify and synthesize against an exact check",
        "",
        f"**{verdict}**: false holds, stated envelopes or decay rates above the exact ones, "
        "and exceptions that are not typed refusals each fail the audit.",
        "",
        f"Seed {args.seed}; {summary['cases']} random certify cases (plus "
        f"{summary['refused_not_hurwitz'] + summary['refused_hurwitz']} refused), "
        f"{summary['synthesis_requests']} synthesis requests; exact check in mpmath "
        f"({DPS} digits, two more per decade of pole damping below 1e-10; K with {DPS_K}). "
        f"Command: `python analysis/certify_audit.py --seed {args.seed} --cases {args.cases} "
        f"--synth {args.synth} --workers {args.workers}`. Times are wall-clock per call on the "
        f"machine that ran it ({args.workers} worker processes).",
        "",
        "Cases: a1 1e3..1e9, damping 0.01..1, beta 0.03..5, gamma of both signs (|gamma| up to "
        "1.3 beta), poles typical / slow / fast / spread / clustered, and a real pole with a "
        "pair of damping 1e-9..1e-3 (lightly damped), 1e-14..1e-9 (near marginal) or "
        "1e-18..1e-14 (beyond double precision), v 1e-3..1e7 V/s, dt 1 us..1 ms, 30 % with a "
        "requested decay.",
        "",
        "| tier | holds | false holds | envelope above exact | decay above exact | "
        "no envelope stated | certifiable | misses (of them, no envelope stated) | miss rate | "
        "stated envelope within 1 % | max envelope error |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for tier, s in summary["tiers"].items():
        head = (
            f"| {tier} | {s['holds']} | {s['false_holds']} | {s['overstated']} | "
            f"{s['decay_overstated']} | {s['undecided']} "
        )
        if tier == "theorem1":
            lines.append(head + "| - | - | - | - | - |")
            continue
        lines.append(
            head + f"| {s['certifiable']} | {s['misses']} ({s['misses_undecided']}) "
            f"| {100 * s['miss_rate']:.2f} % | {s['envelope_within_1pct']} / "
            f"{s['envelope_stated_finite']} ({100 * s['envelope_within_1pct_fraction']:.2f} %) | "
            f"{s['envelope_max_rel_err']:.2e} |"
        )
    lines += [
        "",
        "| pole pattern | cases | refused (GainError) | tier envelopes above exact | "
        "no envelope stated | misses | false holds |",
        "|---|---|---|---|---|---|---|",
    ]
    for pat, r in summary["patterns"].items():
        lines.append(
            f"| {pat} | {r['cases']} | {r['refused']} | {r['overstated']} | {r['undecided']} | "
            f"{r['misses']} | {r['false_holds']} |"
        )
    lines += [
        "",
        f"- Refused with GainError: {summary['refused_not_hurwitz']} whose gains are not "
        f"Hurwitz in exact arithmetic (right), {summary['refused_hurwitz']} that are (a "
        "refusal, not a claim).",
    ]
    lines += [
        "",
        f"- Exceptions raised by certify/synthesize: {summary['exceptions']}.",
        f"- Monotone tiers (theorem1 => lipschitz => sector): {summary['monotone_violations']} "
        "violations.",
        f"- Pole-matched K against mpmath Ackermann: max relative error "
        f"{summary['K_rel_err_max']:.2e}; {summary['K_within_1e-9']} / {summary['cases']} "
        "within 1e-9.",
    ]
    for label in ("wall", "cpu"):
        t = summary[f"certify_{label}_time_s"]
        lines.append(
            f"- certify {label} time per call: median {t['median']:.3f} s, p95 {t['p95']:.3f} s, "
            f"max {t['max']:.3f} s."
        )
    if "synthesis_feasible" in summary:
        lines.append(
            f"- synthesis: {summary['synthesis_feasible']} / {summary['synthesis_requests']} "
            f"feasible; wrong 'infeasible' (an exact search found gains): "
            f"{summary['synthesis_wrong_infeasible']}; feasible answers failing a requested "
            f"property when checked exactly: {summary['synthesis_feasible_property_failures']}."
        )
        for label in ("wall", "cpu"):
            ts = summary[f"synthesis_{label}_time_s"]
            lines.append(
                f"- synthesis {label} time per call: median {ts['median']:.3f} s, p95 "
                f"{ts['p95']:.3f} s, max {ts['max']:.3f} s."
            )
        for s in summary["synthesis_infeasible_answers"]:
            lines.append(f"- 'no' answer {s['request']} ({s['binding']}): {s['reason']}")
    findings = [
        (c["case"], c["pattern"], tier, r.get("max_udot"), r.get("exact"), r["status"][:100])
        for c in cases
        for tier, r in c["tiers"].items()
        if r.get("false_hold") or r["overstated"] or r["decay_overstated"]
    ][:20]
    if findings:
        lines += ["", "Findings (first 20): case, pattern, tier, stated, exact, status", ""]
        lines += [f"- {f[0]} {f[1]} {f[2]} {f[3]!r} {f[4]!r}: {f[5]}" for f in findings]
    misses = [
        (c["case"], tier, c["udot_max"], r["exact"], r["status"][:100])
        for c in cases
        for tier, r in c["tiers"].items()
        if r.get("miss")
    ][:20]
    if misses:
        lines += ["", "Misses (first 20): case, tier, v, exact envelope, status", ""]
        lines += [f"- {m[0]} {m[1]} v={m[2]:.4g} exact={m[3]:.4g}: {m[4]}" for m in misses]
    lines.append("")
    return "\n".join(lines)


def _warm() -> None:
    """The first call compiles the cvxpy programs; not part of the timing."""
    from bwdesign import preset

    certify(preset("paper_experiment"), (8, 64, -512), udot_max=361, dt=2e-4)


def _job(job: tuple) -> dict:
    """One case or request, seeded by ``(seed, index)`` so the campaign splits across workers."""
    kind, seed, i, search = job
    if kind == "case":
        return run_case(np.random.default_rng([seed, i]), i)
    return run_synthesis(np.random.default_rng([seed, 1_000_000 + i]), i, search)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--cases", type=int, default=1000)
    ap.add_argument("--synth", type=int, default=100)
    ap.add_argument("--search", type=int, default=200, help="exact-search pole sets per 'no'")
    ap.add_argument("--out", type=Path, default=Path("reports/audit"))
    ap.add_argument("--workers", type=int, default=1, help="worker processes")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    jobs = [("case", args.seed, i, args.search) for i in range(args.cases)]
    jobs += [("synth", args.seed, i, args.search) for i in range(args.synth)]
    if args.workers > 1:
        import multiprocessing

        with multiprocessing.get_context("fork").Pool(args.workers, initializer=_warm) as pool:
            results = pool.map(_job, jobs, chunksize=4)
    else:
        _warm()
        results = [_job(j) for j in jobs]
    cases = [r for j, r in zip(jobs, results, strict=True) if j[0] == "case"]
    synth = [r for j, r in zip(jobs, results, strict=True) if j[0] == "synth"]
    summary = summarise(cases, synth)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "certify_audit.json").write_text(
        json.dumps({"summary": summary, "cases": cases, "synthesis": synth}, separators=(",", ":"))
        + "\n"
    )
    (args.out / "certify_audit.md").write_text(markdown(summary, args, cases))
    print(markdown(summary, args, cases))
    print(f"wall time {time.perf_counter() - t_start:.0f} s")
    return 0 if summary["failures"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
