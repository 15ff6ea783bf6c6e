"""Exact envelopes of the certificate tiers from frequency-domain conditions.

The hysteresis error enters the observer error dynamics as a rank-one,
single-input perturbation ``x' = (A - k b e3') x`` with ``k`` in an interval
``[k1, k2]`` that contains 0 (continuous tiers), or ``x+ = (A_1 - k' dt b e3') x``
written in delta form ``(x+ - x)/dt = (A_delta - k' b e3') x`` (sampled tier).
For such a family a common quadratic Lyapunov function with decay ``mu``
exists exactly when (S-procedure with one constraint is lossless; KYP lemma)
the nominal system is stable with decay ``mu`` and the circle criterion holds
on the shifted stability boundary::

    q(omega) = 1 + (k1 + k2) Re G + k1 k2 |G|^2 > 0   for every omega,
    G = e3' (sigma(omega) I - A)^-1 b,

with ``sigma = -mu + j omega`` (continuous) or
``sigma = (exp(-mu dt + j omega dt) - 1)/dt``, ``0 <= omega <= pi/dt``
(sampled, delta form). ``k1 = -L``, ``k2 = L`` is the bounded-real
(lipschitz) case, ``q = 1 - L^2 |G|^2``.

For one frequency the admissible intervals are nested (``G`` must lie in the
disk with diameter ``[-1/k2, -1/k1]``), so each frequency admits the rates
``[0, v*(omega))`` and the envelope is ``min_omega v*(omega)``. It is found on a
grid that contains, for every pole of ``G``, points spaced by a fraction of
the pole's distance to the contour (a resonance of width ``h`` is sampled at
``h/2``), then refined by bounded Brent searches around every local extremum.
Everything is evaluated in the scaled coordinates of :mod:`.checks` (time in
``1/sqrt(a1)``), where the resolvent is well conditioned.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["RankOneFamily", "continuous_family", "sampled_family"]

#: Relative resolution of the decay-rate bisection (the envelope itself is refined by
#: Brent to about 1e-9).
DECAY_RTOL = 1e-7
_T = (-8.0, -4.0, -2.0, -1.0, -0.5, -0.25, 0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0)


def _expm1c(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=complex)
    a, b = x.real, x.imag
    return np.expm1(a) * np.cos(b) - 2.0 * np.sin(b / 2.0) ** 2 + 1j * np.exp(a) * np.sin(b)


@dataclass(frozen=True)
class RankOneFamily:
    """``A - k b e3'`` in scaled units (time ``1/w``), continuous or delta form.

    Attributes
    ----------
    Ahat : ndarray, shape (3, 3)
        Scaled nominal matrix (continuous ``A/w`` or delta form ``A_delta/w``).
    bhat : ndarray, shape (3,)
        Scaled input direction.
    w : float
        Time scale (rad/s); ``k`` in 1/s maps to ``k/w``.
    dt : float or None
        Sample time (s) for the delta form; ``None`` for continuous time.
    """

    Ahat: np.ndarray
    bhat: np.ndarray
    w: float
    dt: float | None

    # -- nominal stability with decay mu (1/s) ----------------------------------
    def poles(self) -> np.ndarray:
        """Eigenvalues of the nominal matrix (1/s; delta-form values when sampled)."""
        return np.linalg.eigvals(self.Ahat) * self.w

    def decay_cap(self) -> float:
        """The nominal decay rate (1/s): no decay beyond it is certifiable."""
        lam = self.poles()
        if self.dt is None:
            return float(-np.max(lam.real))
        dt = self.dt
        m2 = dt * (2.0 * lam.real + dt * np.abs(lam) ** 2)  # |z|^2 - 1
        if np.any(m2 <= -1.0):
            worst = float(np.max(m2))
            return math.inf if worst <= -1.0 else -0.5 * math.log1p(worst) / dt
        return float(-0.5 * np.log1p(np.max(m2)) / dt)

    # -- the contour ----------------------------------------------------------------
    def _sigma(self, omega: np.ndarray, mu: float) -> np.ndarray:
        omega = np.asarray(omega, dtype=float)
        if self.dt is None:
            return (-mu + 1j * omega) / self.w
        return _expm1c(-mu * self.dt + 1j * omega * self.dt) / (self.dt * self.w)

    def omega_end(self) -> float:
        return math.inf if self.dt is None else math.pi / self.dt

    def stability_radius(self, mu: float) -> float:
        """``min_omega sigma_min(sigma(omega) I - Ahat)`` over :meth:`grid` (scaled units).

        The smallest perturbation (2-norm) of the scaled nominal matrix that puts a pole
        on the contour (the decay line or circle), sampled on the pole-adapted grid.
        """
        om = self.grid(mu)
        sig = np.atleast_1d(self._sigma(om, mu))
        M = sig[:, None, None] * np.eye(3)[None] - self.Ahat[None].astype(complex)
        return float(np.min(np.linalg.svd(M, compute_uv=False)[:, -1]))

    def G(self, omega: np.ndarray, mu: float) -> np.ndarray:
        """``e3' (sigma I - A)^-1 b`` on the contour, in scaled units (``k G = khat Ghat``).

        By the adjugate of the 3x3 matrix ``M = sigma I - Ahat`` (entries of order
        one in the scaled coordinates): ``e3' adj(M) b / det(M)``; :data:`ON_POLE` at a
        pole exactly on the contour.
        """
        sig = np.atleast_1d(self._sigma(omega, mu))
        with np.errstate(divide="ignore", invalid="ignore"):
            G = _resolvent(sig, self.Ahat, self.bhat)
        return np.where(np.isfinite(G), G, ON_POLE)

    def G1(self, omega: float, mu: float) -> complex:
        """:meth:`G` at one frequency, in plain Python (the refinement's inner loop)."""
        if self.dt is None:
            sig = complex(-mu, omega) / self.w
        else:
            x = complex(-mu * self.dt, omega * self.dt)
            a, b = x.real, x.imag
            e = complex(
                math.expm1(a) * math.cos(b) - 2.0 * math.sin(b / 2.0) ** 2,
                math.exp(a) * math.sin(b),
            )
            sig = e / (self.dt * self.w)
        try:
            return _resolvent_scalar(sig, self._rows, self._b)
        except ZeroDivisionError:
            return complex(ON_POLE)

    @functools.cached_property
    def _rows(self) -> tuple[tuple[float, ...], ...]:
        return tuple(tuple(float(x) for x in row) for row in self.Ahat)

    @functools.cached_property
    def _b(self) -> tuple[float, ...]:
        return tuple(float(x) for x in self.bhat)

    def grid(self, mu: float) -> np.ndarray:
        """Frequencies (rad/s): log grid plus points around every pole."""
        lam = self.poles()
        if self.dt is None:
            cen = np.abs(lam.imag)
            h = np.abs(lam.real + mu)
        else:
            dt = self.dt
            z = 1.0 + dt * lam
            cen = np.abs(np.arctan2(dt * lam.imag, 1.0 + dt * lam.real)) / dt
            r = math.exp(-mu * dt)
            m2 = dt * (2.0 * lam.real + dt * np.abs(lam) ** 2) + (-math.expm1(-2 * mu * dt))
            h = np.abs(m2 / (np.abs(z) + r)) / (r * dt)
        scale = np.abs(lam)
        lo = max(float(scale[scale > 0].min()) if np.any(scale > 0) else self.w, 1e-12) * 1e-4
        hi = max(float(scale.max()), self.w) * 1e4
        end = self.omega_end()
        if math.isfinite(end):
            hi = min(hi, end)
        pts = [np.array([0.0]), np.geomspace(min(lo, hi / 10), hi, 240)]
        for c, hh, s in zip(cen, h, scale, strict=True):
            hh = max(hh, 1e-12 * max(s, self.w))
            pts.append(c + hh * np.array(_T))
            pts.append(np.array([s]))
        if math.isfinite(end):
            pts.append(np.array([end]))
        om = np.concatenate(pts)
        om = om[(om >= 0) & (om <= (end if math.isfinite(end) else np.inf))]
        return np.unique(om)

    # -- searches ---------------------------------------------------------------------
    def _refine(
        self,
        f: Callable[[float], float],
        om: np.ndarray,
        vals: np.ndarray,
        n: int = 4,
        enough: Callable[[float], bool] | None = None,
    ) -> float:
        """Largest value of ``f`` over frequency: grid maxima refined by bounded Brent.

        ``enough``: a test that stays true once it holds for a lower bound of the
        largest value (it asks "is the maximum at least ..."). The searches stop as
        soon as it holds for the best value so far, which is then returned: a lower
        bound that decides the caller's question as the maximum would (the grid and the
        searches run in the same order either way, so an answer that does not stop is
        the maximum itself, bit for bit).
        """
        best = float(np.max(vals))
        if enough is not None and enough(best):
            return best
        from scipy.optimize import minimize_scalar  # here: bwdesign's import stays light

        idx = [
            i
            for i in range(len(om))
            if vals[i] >= (vals[i - 1] if i > 0 else -np.inf)
            and vals[i] >= (vals[i + 1] if i + 1 < len(om) else -np.inf)
        ]
        idx = sorted(idx, key=lambda i: -vals[i])[:n]
        for i in idx:
            a = om[max(i - 1, 0)]
            b = om[min(i + 1, len(om) - 1)]
            if b <= a:
                continue
            # searched in the bracket's own coordinate t in [0, 1]: the bounded search's
            # tolerance is relative to |x|, which at a resonance of width h far out in
            # frequency (h << 1e-8 omega, a lightly damped pair) is wider than the peak
            res = minimize_scalar(
                lambda t, a=a, b=b: -f(a + (b - a) * t),
                bounds=(0.0, 1.0),
                method="bounded",
                options={"xatol": 1e-10},
            )
            best = max(best, -float(res.fun), float(vals[i]))
            if enough is not None and enough(best):
                return best
        return best

    def inverse_envelope(
        self, a: float, b: float, mu: float, *, enough: Callable[[float], bool] | None = None
    ) -> float:
        """Continuous: ``max_omega w(omega)`` for the sector ``[a v, b v]`` (units V/s ^-1).

        ``w`` is the positive root of ``w^2 + (a + b) Re G w + a b |G|^2 = 0``;
        the envelope is ``1 / max w``. ``enough``: stop at a lower bound of the
        maximum for which it holds (see :meth:`_refine`).
        """
        ah, bh = a / self.w, b / self.w

        def wfun(G: np.ndarray) -> np.ndarray:
            S = (ah + bh) * G.real
            Q = ah * bh * np.abs(G) ** 2
            disc = np.sqrt(np.maximum(S * S - 4.0 * Q, 0.0))
            with np.errstate(divide="ignore", invalid="ignore"):
                w_neg = (-S + disc) / 2.0
                w_pos = np.where(S + disc > 0, -2.0 * Q / (S + disc), 0.0)
            return np.maximum(np.where(S < 0, w_neg, w_pos), 0.0)

        om = self.grid(mu)
        vals = wfun(self.G(om, mu))

        def w1(x: float) -> float:
            return _w_scalar(self.G1(x, mu), ah, bh)

        return self._refine(w1, om, vals, enough=enough)

    def min_q(
        self, k1: float, k2: float, mu: float, *, enough: Callable[[float], bool] | None = None
    ) -> float:
        """``min_omega q(omega)`` for the interval ``[k1, k2]`` (1/s).

        ``enough``: a test that stays true once it holds for an upper bound of the
        minimum (e.g. ``q <= 0``); the search stops at the first upper bound for which
        it holds and returns it (see :meth:`_refine`).
        """
        k1h, k2h = k1 / self.w, k2 / self.w

        def q(G: np.ndarray) -> np.ndarray:
            return 1.0 + (k1h + k2h) * G.real + k1h * k2h * np.abs(G) ** 2

        om = self.grid(mu)
        vals = -q(self.G(om, mu))

        def negq(x: float) -> float:
            G = self.G1(x, mu)
            return -(1.0 + (k1h + k2h) * G.real + k1h * k2h * (G.real**2 + G.imag**2))

        stop = None if enough is None else (lambda best: enough(-best))
        return -self._refine(negq, om, vals, enough=stop)

    def envelope_by_bisection(
        self, kfun: Callable[[float], tuple[float, float]], mu: float, v_max: float
    ) -> float:
        """``min_omega v*(omega)`` for a nonlinear interval ``kfun(v)`` (sampled tier).

        ``v*(omega)`` is found for all grid frequencies at once by bisection in
        ``log v`` (the admissible set of one frequency is ``[0, v*)``), then the
        minimum is refined by Brent with a scalar root search per frequency.
        """
        if self.min_q(*kfun(v_max), mu, enough=lambda q: q <= 0) > 0:
            return math.inf

        def qv(G: np.ndarray, v: np.ndarray) -> np.ndarray:
            ks = [kfun(float(x)) for x in np.atleast_1d(v)]
            k1 = np.array([k[0] for k in ks]) / self.w
            k2 = np.array([k[1] for k in ks]) / self.w
            return 1.0 + (k1 + k2) * G.real + k1 * k2 * np.abs(G) ** 2

        from scipy.optimize import brentq  # here: bwdesign's import stays light

        om = self.grid(mu)
        G = self.G(om, mu)
        lo = np.full(om.shape, math.log(v_max) - 80.0)
        hi = np.full(om.shape, math.log(v_max))
        ok_top = qv(G, np.exp(hi)) > 0
        for _ in range(60):
            mid = (lo + hi) / 2.0
            good = qv(G, np.exp(mid)) > 0
            lo = np.where(good, mid, lo)
            hi = np.where(good, hi, mid)
        vstar = np.where(ok_top, math.inf, np.exp(hi))

        def inv_vstar_at(x: float) -> float:
            Gx = np.array([self.G1(x, mu)])

            def f(lv: float) -> float:
                return float(qv(Gx, np.array([math.exp(lv)]))[0])

            top = math.log(v_max)
            if f(top) > 0:
                return 0.0
            bot = top - 80.0
            if f(bot) <= 0:
                return math.inf
            return math.exp(-brentq(f, bot, top, xtol=1e-14, rtol=1e-15))

        finite = np.isfinite(vstar)
        inv = np.where(finite, 1.0 / np.where(finite, vstar, 1.0), 0.0)
        best = self._refine(inv_vstar_at, om, inv)
        return math.inf if best <= 0 else 1.0 / best

    def largest_decay(self, feasible: Callable[[float], bool]) -> float:
        """Largest ``mu`` in ``[0, decay_cap)`` with ``feasible(mu)`` (bisection, monotone)."""
        cap = self.decay_cap()
        if not (cap > 0) or not feasible(0.0):
            return 0.0
        if not math.isfinite(cap):
            cap = 50.0 / (self.dt or 1.0)
        lo, hi = 0.0, cap
        while hi - lo > DECAY_RTOL * hi:
            mid = (lo + hi) / 2.0
            if feasible(mid):
                lo = mid
            else:
                hi = mid
        return lo


#: ``G`` at a pole exactly on the contour (near-marginal gains in double precision): large
#: enough that no rate is certified there, small enough that ``|G|^2`` stays finite.
ON_POLE = 1e150


def _resolvent(sig: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    m00, m01, m02 = sig - A[0, 0], -A[0, 1], -A[0, 2]
    m10, m11, m12 = -A[1, 0], sig - A[1, 1], -A[1, 2]
    m20, m21, m22 = -A[2, 0], -A[2, 1], sig - A[2, 2]
    c0 = m10 * m21 - m11 * m20
    c1 = m01 * m20 - m00 * m21
    c2 = m00 * m11 - m01 * m10
    det = m00 * (m11 * m22 - m12 * m21) - m01 * (m10 * m22 - m12 * m20) + m02 * c0
    return (c0 * b[0] + c1 * b[1] + c2 * b[2]) / det


def _resolvent_scalar(sig: complex, A: tuple, b: tuple) -> complex:
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = A
    m00, m11, m22 = sig - a00, sig - a11, sig - a22
    c0 = a10 * a21 - m11 * -a20
    c1 = a01 * a20 - m00 * -a21
    c2 = m00 * m11 - a01 * a10
    det = m00 * (m11 * m22 - a12 * a21) + a01 * (-a10 * m22 - a12 * a20) - a02 * c0
    return (c0 * b[0] + c1 * b[1] + c2 * b[2]) / det


def _w_scalar(G: complex, ah: float, bh: float) -> float:
    """``wfun`` of :meth:`RankOneFamily.inverse_envelope` at one ``G``, in plain Python.

    The same operations in the same order as the array version (``|G|`` by numpy,
    whose complex modulus is not Python's in the last bit; ``|G|^2`` as ``|G| |G|``,
    as numpy squares; ``maximum`` keeping a NaN), so the value is bit for bit the
    array version's, some ten times faster per call.
    """
    S = (ah + bh) * G.real
    g = float(np.abs(np.complex128(G)))
    Q = ah * bh * (g * g)
    d = S * S - 4.0 * Q
    disc = math.sqrt(d if (d > 0.0 or d != d) else 0.0)
    if S < 0:
        w = (-S + disc) / 2.0
    else:
        w = -2.0 * Q / (S + disc) if S + disc > 0 else 0.0
    return w if (w > 0.0 or w != w) else 0.0


def continuous_family(Ahat: np.ndarray, w: float) -> RankOneFamily:
    """The continuous family ``A - k e3 e3'`` (scaled ``Ahat``, time scale ``w``)."""
    return RankOneFamily(np.asarray(Ahat, float), np.array([0.0, 0.0, 1.0]), float(w), None)


def sampled_family(Adelta: np.ndarray, b: np.ndarray, s: np.ndarray, w: float, dt: float):
    """The sampled family in delta form, scaled by ``S = diag(s)`` (``s[2] = 1``) and ``w``."""
    Ah = np.asarray(Adelta, float) * s[None, :] / s[:, None] / w
    bh = np.asarray(b, float) / s
    return RankOneFamily(Ah, bh, float(w), float(dt))
