"""Peak-to-peak (l-infinity induced) bounds of a sampled error system, per plant.

For ``z+ = A(rho_k) z + B(rho_k) f_k`` with ``|f_j| <= W_j`` at every sample and
``rho_k`` anywhere in ``[rho_c - h, rho_c + h]`` (affine, as the PHSO's jump slope
enters), the steady peak of an output ``l'z`` is bounded by the l1 norms of the
impulse responses of the middle system, ``L1(l, b) = sum_k |l' A_c^k b|``
(exact for a fixed ``rho``: a sign pattern of ``f`` attains it), and a small gain
for the time-varying part. That part is rank one in the PHSO loop (``rho``
multiplies the posterior ``x3`` error): ``[E, E_B] = sigma u [v; v_s]'``, so it is
one more input ``psi = (rho_k - rho_c) sigma (v'z + v_s'f)`` along ``u`` with
``|psi| <= h sigma eta``, ``eta = sup |v'z + v_s'f|``, and::

    eta <= (sum_j W_j L1(v, b_j) + |v_s|'W) / (1 - h sigma L1(v, u))   (if < 1)
    sup |l'z| <= sum_j W_j L1(l, b_j) + h sigma L1(l, u) eta

The sums run until the rest is below a millionth of them; the rest is bounded and
added: with ``P = dlyap((A/r)', I)`` for ``r`` between the spectral radius and 1,
``|l' A^k b| <= r^k sqrt(l'P^-1 l) sqrt(b'Pb)``. All of it is computed in balanced
coordinates (:func:`scipy.linalg.matrix_balance`: a diagonal similarity of powers of 2,
so ``L A^k B`` is unchanged and exact): on the stiff loops ``P`` of the unbalanced
matrix has a condition number of 1e16 and fails its check (paper_simulation_corrected,
+-5 % box), balanced about 5e5.

Compared with the common ellipsoid (:mod:`.robust`), which bounds every output of
every plant with one quadratic function, this is the tightest bound of its inputs'
kind per plant; :func:`bwdesign.certify_robust` keeps the smaller of the two.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.linalg import LinAlgWarning, matrix_balance, solve_discrete_lyapunov

__all__ = ["l1_norms", "peak_bounds", "peak_parts", "decreasing_lyapunov"]

#: Stop the sums once the rest is below this share of them.
_REST = 1e-6
#: ... or after this many terms (the rest is then added, however large).
_MAX_TERMS = 400_000
_CHUNK = 512


def l1_norms(A: np.ndarray, B: np.ndarray, L: np.ndarray) -> np.ndarray | None:
    """``sum_k |L A^k B|`` entrywise (shape ``(rows, cols)``), with the rest bounded and
    added; ``None`` for an ``A`` that is not stable."""
    # A_b = T^-1 A T, T = diag(scale) of powers of 2: L A^k B = (L T) A_b^k (T^-1 B), exactly
    A, (scale, _) = matrix_balance(A, permute=False, separate=True)
    L, B = L * scale, B / scale[:, None]
    rad = float(np.max(np.abs(np.linalg.eigvals(A))))
    if not rad < 1:
        return None
    r = 0.5 * (1 + rad) if rad > 0 else 0.5
    P = decreasing_lyapunov(A / r)
    if P is None:
        return None
    try:
        Pi = np.linalg.inv(P)
    except np.linalg.LinAlgError:
        return None
    gl = np.sqrt(np.maximum(np.einsum("ri,ij,rj->r", L, Pi, L), 0.0))
    gb = np.sqrt(np.maximum(np.einsum("ic,ij,jc->c", B, P, B), 0.0))
    total = np.zeros((L.shape[0], B.shape[1]))
    row = L.copy()
    k = 0
    # powers A^0..A^(CHUNK-1) by doubling (log2(CHUNK) batched products), then blocks of
    # rows advanced CHUNK steps at a time; one block's terms are one matrix product
    n, cols = B.shape
    pw = np.empty((_CHUNK, n, n))
    pw[0] = np.eye(n)
    step, h = A, 1
    while h < _CHUNK:
        pw[h : 2 * h] = pw[:h] @ step
        step, h = step @ step, 2 * h
    A_chunk = step  # A^CHUNK
    PB = np.ascontiguousarray((pw @ B).transpose(1, 0, 2)).reshape(n, _CHUNK * cols)
    while True:
        total += np.abs(row @ PB).reshape(-1, _CHUNK, cols).sum(axis=1)
        k += _CHUNK
        row = row @ A_chunk
        rest = (r**k / (1 - r)) * np.outer(gl, gb)
        if np.all(rest <= _REST * np.maximum(total, 1e-300)) or k >= _MAX_TERMS:
            return total + rest
        if not np.all(np.isfinite(row)):
            return None


def decreasing_lyapunov(A: np.ndarray) -> np.ndarray | None:
    """``P`` with ``A'PA - P = -I`` (scipy's direct solve), kept only when checked here.

    The rest bounds built on ``P`` need ``P > 0`` and ``P - A'PA >= 0`` (``x'Px`` does
    not grow along ``x+ = Ax``), nothing more. On stiff loops scipy solves the Kronecker
    system with a reciprocal condition number of 1e-22 to 1e-25 and warns; its ``P``
    passes the check all the same (measured on the stack: ``P - A'PA`` has every
    eigenvalue within 2e-5 of 1), so the warning is not shown and the check decides:
    the computed eigenvalues of both symmetric parts must be positive. This catches a
    failed solve, and it is a check in floating point, not an enclosure: the worst-case
    rounding of forming ``P - A'PA`` (``8 n^2 eps |P| |A|^2`` in balanced coordinates)
    exceeds its smallest eigenvalue on the stiff loops (0.03 of it on the stack, 5e-4
    on paper_simulation_corrected). ``None`` when the check or the solve fails.
    """
    n = A.shape[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LinAlgWarning)
        try:
            P = solve_discrete_lyapunov(A.T, np.eye(n))
        except (np.linalg.LinAlgError, ValueError):
            return None
    if not np.all(np.isfinite(P)):
        return None
    S = 0.5 * (P + P.T)
    M = S - A.T @ S @ A
    if not (np.linalg.eigvalsh(S)[0] > 0.0 and np.linalg.eigvalsh(0.5 * (M + M.T))[0] > 0.0):
        return None
    return P


def peak_bounds(
    blocks: list[tuple[np.ndarray, np.ndarray]],
    rhos: tuple[float, ...],
    W: np.ndarray,
    rows: np.ndarray,
) -> np.ndarray | None:
    """Steady bounds of ``sup |rows z|`` for one plant (see the module doc).

    ``blocks``: ``(A, B)`` at each end of ``rhos`` (one block: ``rho`` fixed); ``W``
    the bounds of ``B``'s columns. ``None``: unstable, or the small gain fails.
    """
    t = _terms(blocks, rhos, W, rows)
    if t is None:
        return None
    _, W, L1, rank_one = t
    if rank_one is None:
        return L1 @ W
    g, vs, gain = rank_one
    eta = (L1[-1, :-1] @ W + np.abs(vs) @ W) / (1 - gain)
    out = L1[:-1, :-1] @ W + g * L1[:-1, -1] * eta
    return out if np.all(np.isfinite(out)) else None


def peak_parts(
    blocks: list[tuple[np.ndarray, np.ndarray]],
    rhos: tuple[float, ...],
    W: np.ndarray,
    rows: np.ndarray,
) -> np.ndarray | None:
    """What each input channel adds to :func:`peak_bounds`: ``(rows, len(W))``, each row
    summing to that bound (to rounding; both are linear in ``W``), 0 where ``W_j = 0``.
    Where the small gain acts, channel ``j``'s part includes its share of ``eta``."""
    t = _terms(blocks, rhos, W, rows)
    if t is None:
        return None
    keep, Wk, L1, rank_one = t
    out = np.zeros((rows.shape[0], len(keep)))
    if rank_one is None:
        out[:, keep] = L1 * Wk
        return out
    g, vs, gain = rank_one
    eta = (L1[-1, :-1] + np.abs(vs)) * Wk / (1 - gain)  # channel j's share of eta
    out[:, keep] = L1[:-1, :-1] * Wk + g * L1[:-1, -1][:, None] * eta[None, :]
    return out if np.all(np.isfinite(out)) else None


def _terms(blocks, rhos, W, rows):
    """The l1 norms both functions above combine: ``(keep, W[keep], L1, rank_one)``,
    ``rank_one = (g, v_s, gain)`` where ``rho`` varies (``L1`` then has the ``v`` row and
    the ``u`` column last), None for a fixed ``rho``; None: unstable, not rank one, or
    the small gain fails."""
    keep = W > 0
    W = W[keep]
    A_c = np.mean([A for A, _ in blocks], axis=0)
    B_c = np.mean([B[:, keep] for _, B in blocks], axis=0)
    if len(blocks) == 1:
        L1 = l1_norms(A_c, B_c, rows)
        return None if L1 is None else (keep, W, L1, None)
    (A0, B0), (A1, B1) = blocks
    span = rhos[1] - rhos[0]
    D = np.hstack([A1 - A0, (B1 - B0)[:, keep]]) / span
    U, S, Vt = np.linalg.svd(D)
    if S[0] == 0:
        L1 = l1_norms(A_c, B_c, rows)
        return None if L1 is None else (keep, W, L1, None)
    if S[1] > 1e-9 * S[0]:  # not rank one: no scalar small gain here
        return None
    n = A_c.shape[0]
    u, v, vs = U[:, 0], Vt[0, :n], Vt[0, n:]
    g = 0.5 * span * S[0]
    L1 = l1_norms(A_c, np.column_stack([B_c, u]), np.vstack([rows, v]))
    if L1 is None:
        return None
    gain = g * L1[-1, -1]
    if not gain < 1:
        return None
    return keep, W, L1, (g, vs, gain)
