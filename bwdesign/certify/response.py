"""The loop's exact response to its reference, and its supremum over every sample.

A certificate that bounds the reference's terms by their worst case at every sample
(:func:`bwdesign.model.reference_cover.sup_abs`) lets them change sign every sample;
a reference does not. The part of the error system driven by the reference alone,
``zr+ = A zr + B r_k`` with ``r_k = M sigma(t_k)`` at the loop's own samples
``t_k = k dt`` (as every simulator runs it), is a deterministic sequence: this module
computes it and bounds ``sup_k |L zr_k + Lr r_k|`` (or of its increments) over every
``k`` in steady state:

- a periodic reference whose period is a rational multiple ``num / den`` of ``dt``
  (every decimal frequency is) repeats every ``num`` samples: the periodic steady
  state ``zr_0 = (I - A^num)^-1 sum_m A^(num-1-m) B r_m`` is computed and the period
  run once more, its end checked against its start;
- a reference that settles (a step) is run from the equilibrium of its initial value
  through its last move, then until the rest ``|L (zr_k - zr_inf)| <= sqrt(L P^-1 L')
  sqrt(V_k)`` (``V = e'Pe``, ``A'PA - P = -I``, non-increasing) is small; that rest is
  added.

A sample instant within rounding of a breakpoint of the reference (a triangle's blend
edge at ``k dt`` exactly) may see either side of a jump in ``x_d''``: each such
sample is a class ``c`` whose response to the jump ``y_c`` is computed too, and the
bound is the largest over every choice, ``max_k max(y + sum y_c^+, -y + sum y_c^-)``.
Rounding of the periodic solve is bounded through the same ``P`` and added.

Returns ``None`` (the caller then falls back to the worst case at every sample) for a
reference that is neither, a period that is not a small rational multiple of ``dt``,
or an ill-conditioned periodic solve.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from ..model.references import Reference
from .peak import decreasing_lyapunov

__all__ = ["response_sups", "MAX_PERIOD_SAMPLES"]

#: Longest repeating sequence (samples) solved as a periodic steady state.
MAX_PERIOD_SAMPLES = 400_000
#: A sample this close to a breakpoint (in units of dt) may see either side of it.
_AMBIGUOUS = 1e-6
#: Samples run per chunk at most (memory: chunk x plants x states x classes) ...
_CHUNK = 1024
#: ... and at most this many values per chunk array (16 MB): a box's hundreds of plants
#: with a triangle's classes held about 900 MB at 1024 samples a chunk
_CHUNK_VALUES = 2_000_000
#: Settling references: stop once the rest is below this share of the supremum.
_REST = 1e-6
#: ... or after this many samples beyond the last move.
_MAX_SETTLE = 200_000


def _period_samples(reference: Reference, dt: float) -> int | None:
    T = reference.period
    if T is None:
        return None
    ratio = T / dt
    fr = Fraction(ratio).limit_denominator(1000)
    if abs(float(fr) - ratio) > 1e-9 * ratio or fr.numerator > MAX_PERIOD_SAMPLES:
        return None
    return int(fr.numerator)


def _sigma(reference: Reference, t: np.ndarray) -> np.ndarray:
    """``(x, v, a)`` at each time, shape ``(len(t), 3)``."""
    x, v, a = (np.asarray(w, float) * np.ones_like(t) for w in reference.evaluate(t))
    return np.stack([x, v, a], axis=1)


def _samples(reference: Reference, dt: float, n: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """``sigma(t_k)`` for ``k < n`` (9 entries, at ``t_k``, ``t_k + dt``, ``t_k + 2 dt``) and
    the ambiguity classes: per sample near a breakpoint, the jump its ``sigma`` may take."""
    t = np.arange(n + 2) * dt
    g = _sigma(reference, t)
    sig = np.concatenate([g[:n], g[1 : n + 1], g[2 : n + 2]], axis=1)
    classes = []
    bps = np.asarray(reference.breakpoints(-dt, t[-1] + dt), float)
    tol = _AMBIGUOUS * dt
    for b in bps:
        k = int(round(b / dt))
        if not 0 <= k < n + 2 or abs(k * dt - b) > tol:
            continue
        lo = _sigma(reference, np.array([b - 4 * tol]))[0]
        hi = _sigma(reference, np.array([b + 4 * tol]))[0]
        here = g[k]
        jump = [lo - here, hi - here]
        for dj in jump:
            if not np.any(np.abs(dj) > 1e-9 * (np.abs(here) + 1e-300)):
                continue
            col = np.zeros((n, 9))
            for shift in range(3):  # sample k - shift sees t_k at position shift
                if 0 <= k - shift < n:
                    col[k - shift, 3 * shift : 3 * shift + 3] = dj
            # a smooth drift of 4 tol is not a jump: keep only the jumping entries
            col[np.abs(col) < 1e-6 * np.max(np.abs(col))] = 0.0
            if np.any(col):
                classes.append(col)
    return sig, classes


class _Rows:
    """The outputs ``y = Lz z + Lr r`` (``Lz`` per plant), some taken as increments."""

    def __init__(self, Lz: np.ndarray, Lr: np.ndarray, incr: np.ndarray):
        self.Lz, self.Lr, self.incr = Lz, Lr, incr
        self.best = np.zeros(Lz.shape[:2])
        self.last: np.ndarray | None = None

    def take(self, Z: np.ndarray, S: np.ndarray) -> None:
        """``Z``: (k, plants, n, classes), ``S``: the samples' sigma (k, 9, classes)."""
        # (matmul, not einsum: the same sums, 13x faster on these stacks)
        Y = np.matmul(self.Lz, Z) + np.matmul(self.Lr, S)[:, None]  # (k, plants, R, classes)
        if self.last is None:  # the first sample has no increment
            D = np.concatenate([np.zeros_like(Y[:1]), np.diff(Y, axis=0)])
        else:
            D = np.diff(np.concatenate([self.last[None], Y]), axis=0)
        self.last = Y[-1]
        self.best = np.maximum(self.best, _worst(np.where(self.incr[None, None, :, None], D, Y)))


def _worst(V: np.ndarray) -> np.ndarray:
    """``max_k`` of the largest ``|base + sum theta_c class_c|`` over ``theta`` in [0, 1]."""
    base, cls = V[..., 0], V[..., 1:]
    up = base + np.maximum(cls, 0).sum(-1)
    dn = -base + np.maximum(-cls, 0).sum(-1)
    return np.maximum(up, dn).max(axis=0)


def _run(A, BM, sig, classes, z0, rows: _Rows | None):
    """Run ``z+ = A z + BM sigma_k`` from ``z0`` (plants, n, classes); the last state."""
    n_s = sig.shape[0]
    S = np.stack([sig] + list(classes), axis=-1)  # (k, 9, classes)
    z = z0.copy()
    width = z0.size + (0 if rows is None else rows.Lz.shape[0] * rows.Lz.shape[1] * S.shape[-1])
    chunk = max(16, min(_CHUNK, _CHUNK_VALUES // max(width, 1)))
    for c0 in range(0, n_s, chunk):
        Sc = S[c0 : c0 + chunk]
        U = np.matmul(BM, Sc[:, None])  # (k, plants, n, classes)
        Z = np.empty_like(U)
        for i in range(len(Sc)):
            Z[i] = z
            z = A @ z + U[i]
        if rows is not None:
            rows.take(Z, Sc)
    return z


def _lyapunov(A: np.ndarray) -> np.ndarray | None:
    """Per plant ``P`` with ``A'PA - P = -I``, each checked (:func:`.peak.decreasing_lyapunov`)."""
    Ps = [decreasing_lyapunov(a) for a in A]
    if any(P is None for P in Ps):
        return None
    P = np.array(Ps)
    return 0.5 * (P + np.swapaxes(P, 1, 2))


def _gain(P: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``sqrt(L P^-1 L')`` per plant and row: ``|L e| <= gain sqrt(e'Pe)``."""
    Pi = np.linalg.inv(P)
    return np.sqrt(np.maximum(np.einsum("prn,pnm,prm->pr", L, Pi, L), 0.0))


def response_sups(
    A: np.ndarray,
    B: np.ndarray,
    M: np.ndarray,
    reference: Reference,
    dt: float,
    rows: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> np.ndarray | None:
    """Bounds of ``sup_k |y_k|`` (steady state) for the response to the reference.

    Parameters
    ----------
    A : ndarray, shape (plants, n, n)
        Stable per plant.
    B : ndarray, shape (plants, n, 5)
        The reference terms' columns; ``r_k = M sigma(t_k)``.
    M : ndarray, shape (5, 9)
    reference : Reference
    dt : float
    rows : (Lz, Lr, incr)
        ``Lz`` (plants, R, n), ``Lr`` (R, 5), ``incr`` (R,) bool: row ``i`` is
        ``y = Lz z + Lr r``, bounded itself or (``incr``) its increment ``y_{k+1} - y_k``.

    Returns
    -------
    ndarray, shape (plants, R), or None when this reference is not covered here.
    """
    Lz, Lr, incr = (np.asarray(x) for x in rows)
    incr = incr.astype(bool)
    BM = B @ M
    P = _lyapunov(A)
    if P is None or np.max(np.abs(np.linalg.eigvals(A))) >= 1:
        return None
    n_p, n = A.shape[:2]
    LrM = Lr @ M
    p = _period_samples(reference, dt)
    if p is not None:
        sig, classes = _samples(reference, dt, p)
        C = 1 + len(classes)
        zp = _run(A, BM, sig, classes, np.zeros((n_p, n, C)), None)
        Ap = np.linalg.matrix_power(A, p)
        G = np.eye(n)[None] - Ap
        if np.max(np.linalg.cond(G)) > 1e10:
            return None
        z0 = np.linalg.solve(G, zp)
        out = _Rows(Lz, LrM, incr)
        z_end = _run(A, BM, sig, classes, z0, out)
        # the increment across the period's end (sample p-1 to p = sample 0)
        Yend = (
            np.einsum("prn,pnc->prc", Lz, z_end)
            + np.einsum("rj,jc->rc", LrM, _wrap(sig, classes))[None]
        )
        wrap = _worst((Yend - out.last)[None])
        out.best = np.where(incr[None], np.maximum(out.best, wrap), out.best)
        # rounding of the periodic solve: e0 = zr_0 - computed, (I - A^p) e0 = z_end - z0
        e0 = np.linalg.solve(G, z_end - z0)
        V = np.einsum("pnc,pnm,pmc->pc", e0, P, e0)
        root_v = np.sqrt(np.maximum(V, 0.0)).sum(-1)
        return out.best + _row_gains(P, A, Lz, incr) * root_v[:, None]
    settle = reference.settles_at
    if settle is None:
        return None
    k_last = int(math.ceil(max(settle, 0.0) / dt)) + 3
    sig, classes = _samples(reference, dt, k_last)
    C = 1 + len(classes)
    u0 = BM @ sig[0]
    z0 = np.zeros((n_p, n, C))
    z0[..., 0] = np.linalg.solve(np.eye(n)[None] - A, u0[..., None])[..., 0]
    out = _Rows(Lz, LrM, incr)
    z = _run(A, BM, sig, classes, z0, out)
    # then the reference is constant: run on until the rest is negligible
    s_inf = sig[-1]
    z_inf = np.linalg.solve(np.eye(n)[None] - A, (BM @ s_inf)[..., None])[..., 0]
    gain = _row_gains(P, A, Lz, incr)
    ran = 0
    z_at = np.zeros_like(z)
    z_at[..., 0] = z_inf  # the classes' inputs are 0 after their sample
    while True:
        e = z - z_at
        V = np.einsum("pnc,pnm,pmc->pc", e, P, e)
        rest = np.sqrt(np.maximum(V, 0)).sum(-1)[:, None] * gain
        y_inf = np.einsum("prn,pn->pr", Lz, z_inf) + (LrM @ s_inf)[None]
        tail = np.where(incr[None], rest, np.abs(y_inf) + rest)
        if np.all(rest <= _REST * np.maximum(out.best, 1e-300)) or ran >= _MAX_SETTLE:
            return np.maximum(out.best, tail)
        steps = _CHUNK * 8
        const = np.repeat(s_inf[None], steps, axis=0)
        z = _run(A, BM, const, [np.zeros_like(const)] * (C - 1), z, out)
        ran += steps


def _wrap(sig: np.ndarray, classes: list[np.ndarray]) -> np.ndarray:
    """The reference terms' ``sigma`` at sample 0 (the next period's first), per class."""
    return np.stack([sig[0]] + [c[0] for c in classes], axis=-1)


def _row_gains(P, A, Lz, incr) -> np.ndarray:
    """Per plant and row, ``g`` with ``|row e| <= g sqrt(e'Pe)`` for the row itself or,
    where ``incr``, its increment ``Lz (A - I) e``: the rest of a decaying ``e``."""
    gain = _gain(P, np.concatenate([Lz, np.einsum("prn,pnm->prm", Lz, A) - Lz], axis=1))
    R = Lz.shape[1]
    return np.where(incr[None], gain[:, R:], gain[:, :R])
