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

import hashlib
import warnings

import numpy as np
from scipy.linalg import LinAlgWarning, matrix_balance, solve_discrete_lyapunov

__all__ = ["l1_norms", "l1_bounded_change", "peak_bounds", "peak_parts", "decreasing_lyapunov"]

#: Stop the sums once the rest is below this share of them.
_REST = 1e-6
#: ... or after this many terms (the rest is then added, however large).
_MAX_TERMS = 400_000
_CHUNK = 512
#: Terms of the bounded-change dual solved on a grid (:func:`l1_bounded_change`), at
#: least and at most; the rest of the response is taken as the quasi-static tail.
_HORIZON = (256, 4096)
#: Points of that grid.
_GRID = 513
#: The bounded-change dual is tried on the rows where that input is at least this share
#: of the plain bound.
_WORTH = 0.05
#: ... and where no input of the class found comes within this share of it.
_CLOSE = 0.02
#: ... and where the input's change per sample is at most this share of its bound. Above
#: it the dual on the grid gained nothing where measured (stack_actuator_800hz, +-5 %
#: box: the jump's change 0.78-0.91 of the jump, the dual 1.01-1.16 times the plain
#: bound on every row tried, at 5 s per certificate); at 0.02 (paper_experiment) it is
#: 0.55-0.87 of it.
_SLOW_CHANGE = 0.25


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


def l1_bounded_change(
    A: np.ndarray, b: np.ndarray, L: np.ndarray, bound: float, change: float
) -> np.ndarray | None:
    """Per row ``l`` of ``L``: a bound of ``sup |sum_k l' A^k b f_(t-k)|`` over every input
    with ``|f_k| <= bound`` *and* ``|f_(k+1) - f_k| <= change``, never above the plain
    ``bound * L1(l, b)``; None for an ``A`` that is not stable.

    The supremum is a linear programme in ``f``; by weak duality every sequence ``mu``
    gives an upper bound: with ``h_k = l' A^k b`` and ``mu_(-1) = 0``,
    ``sum h_k f_(t-k) = sum (h_k - mu_k + mu_(k-1)) f_(t-k) + sum mu_k (f_(t-k) - f_(t-k-1))``,
    so::

        sup <= bound sum |h_k - mu_k + mu_(k-1)| + change sum |mu_k|

    ``mu = 0`` is the plain bound; ``mu_k = -T_k`` (``T_k = sum_(i>k) h_i = l' A^(k+1) Q``,
    ``Q = (I - A)^-1 b``) the quasi-static split of :mod:`.robust` (the first term then
    only ``|l'Q|``). Here ``mu`` is free over the first :data:`_HORIZON` terms and
    ``-T_k`` after them, chosen by dynamic programming over a grid of values of
    ``R_k = C_k - mu_k`` (``C`` the partial sums of ``h``; the dual is an l1 fit of ``C``
    by ``R`` with its total variation charged ``bound``, an l1 distance transform per
    step), and the bound is then evaluated here from that ``mu`` alone (the grid decides
    only how tight it is): the tail ``change sum_(k>=M) |T_k|`` is :func:`l1_norms` of
    ``A^(M+1) Q``, and the sum gets a relative margin for rounding. Tight where the
    input cannot flip sign every sample (the PHSO's hysteresis jump, whose change per
    sample is a small part of it).
    """
    L = np.atleast_2d(L)
    plain = l1_norms(A, b[:, None], L)
    if plain is None:
        return None
    plain = plain[:, 0] * bound
    if not change < 2 * bound or bound == 0:  # the change bound says nothing more
        return plain
    dual = _dual_bound(A, b, L, bound, change, plain)
    return plain if dual is None else np.where(np.isfinite(dual), np.minimum(dual, plain), plain)


def _dual_bound(A, b, L, bound, change, plain) -> np.ndarray | None:
    """:func:`l1_bounded_change`'s dual bound alone, per row; inf on a row where an input
    of the class already comes within :data:`_CLOSE` of ``plain`` (the row's plain bound),
    so the dual could gain little; None: ``I - A`` singular, or the tail's l1 norm fails."""
    n = A.shape[0]
    A, (scale, _) = matrix_balance(A, permute=False, separate=True)
    L, b = L * scale, b / scale
    try:
        Q = np.linalg.solve(np.eye(n) - A, b)
    except np.linalg.LinAlgError:
        return None
    # free mu until the slowest mode has decayed to 1e-4 (within the horizon's bounds)
    rad = float(np.max(np.abs(np.linalg.eigvals(A))))
    M = _HORIZON[0] if rad == 0 else int(np.clip(np.log(1e-4) / np.log(rad), *_HORIZON))
    rows = L.shape[0]
    h = np.empty((rows, M))
    x = b.copy()
    for k in range(M):
        h[:, k] = L @ x
        x = A @ x
    # an input of the class: the worst signs rate limited forwards and backwards in time,
    # averaged (the class is convex; one limiter lags the sign changes, the other leads).
    # Where it attains nearly the plain bound, no dual can be much below it (the terms
    # past M add at most the rest).
    f = np.empty((rows, M))
    want = bound * np.sign(h)
    for order in (range(M), range(M - 1, -1, -1)):
        prev = np.zeros(rows)
        for k in order:
            prev = np.clip(want[:, k], prev - change, prev + change)
            f[:, k] = prev if order.step == 1 else 0.5 * (f[:, k] + prev)
    rest = np.maximum(plain - bound * np.abs(h).sum(axis=1), 0.0)
    worth = (h * f).sum(axis=1) - rest < (1 - _CLOSE) * plain
    out = np.full(rows, np.inf)
    if not np.any(worth):
        return out
    h, L = h[worth], L[worth]
    rows = L.shape[0]
    AMQ = np.linalg.matrix_power(A, M) @ Q
    T_last = L @ AMQ  # T_(M-1)
    S = L @ Q  # the whole sum, where R ends
    tail = l1_norms(A, (A @ AMQ)[:, None], L)
    if tail is None:
        return None
    C = np.cumsum(h, axis=1)
    R = _tv_fit(C, S, bound, change)
    mu = C - R
    res = h - mu + np.hstack([np.zeros((rows, 1)), mu[:, :-1]])
    val = bound * (np.abs(res).sum(axis=1) + np.abs(T_last + mu[:, -1])) + change * (
        np.abs(mu).sum(axis=1) + tail[:, 0]
    )
    out[worth] = val * (1 + 4 * M * np.finfo(float).eps)
    return out


def _tv_fit(C: np.ndarray, S: np.ndarray, lam: float, fit: float) -> np.ndarray:
    """Per row: ``R`` on a grid minimising ``lam (|R_0| + sum |R_k - R_(k-1)| + |S - R_(M-1)|)
    + fit sum |C_k - R_k|`` (dynamic programming with the l1 distance transform)."""
    rows, M = C.shape
    q = np.quantile(C, np.linspace(0, 1, _GRID - 2), axis=1).T
    g = np.sort(np.column_stack([q, np.zeros(rows), S]), axis=1)
    lg = lam * g

    def transform(V):  # min over g' of V(g') + lam |g - g'|, g increasing
        fwd = lg + np.minimum.accumulate(V - lg, axis=1)
        return -lg + np.minimum.accumulate((np.minimum(V, fwd) + lg)[:, ::-1], axis=1)[:, ::-1]

    # kept in single precision for the way back (it only chooses R; the bound is
    # evaluated from R afterwards): 4096 x 6 x 513 values at most, 50 MB
    V = np.empty((M, rows, g.shape[1]), np.float32)
    cur = lam * np.abs(g) + fit * np.abs(C[:, :1] - g)
    V[0] = cur
    for k in range(1, M):
        cur = transform(cur) + fit * np.abs(C[:, k : k + 1] - g)
        V[k] = cur
    at = np.arange(rows)
    i = np.argmin(cur + lam * np.abs(S[:, None] - g), axis=1)
    R = np.empty((rows, M))
    R[:, -1] = g[at, i]
    for k in range(M - 1, 0, -1):
        i = np.argmin(V[k - 1] + lam * np.abs(g - R[:, k : k + 1]), axis=1)
        R[:, k - 1] = g[at, i]
    return R


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
    change: np.ndarray | None = None,
) -> np.ndarray | None:
    """Steady bounds of ``sup |rows z|`` for one plant (see the module doc).

    ``blocks``: ``(A, B)`` at each end of ``rhos`` (one block: ``rho`` fixed); ``W``
    the bounds of ``B``'s columns; ``change``: where finite, a bound on the change of
    that column's input from one sample to the next too (:func:`l1_bounded_change`).
    ``None``: unstable, or the small gain fails.
    """
    t = _terms(blocks, rhos, W, rows, change)
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
    change: np.ndarray | None = None,
) -> np.ndarray | None:
    """What each input channel adds to :func:`peak_bounds`: ``(rows, len(W))``, each row
    summing to that bound (to rounding), 0 where ``W_j = 0``. Where the small gain acts,
    channel ``j``'s part includes its share of ``eta``."""
    t = _terms(blocks, rhos, W, rows, change)
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


def _terms(blocks, rhos, W, rows, change=None):
    """The l1 norms both functions above combine: ``(keep, W[keep], L1, rank_one)``,
    ``rank_one = (g, v_s, gain)`` where ``rho`` varies (``L1`` then has the ``v`` row and
    the ``u`` column last), None for a fixed ``rho``; None: unstable, not rank one, or
    the small gain fails. A column whose input's change is bounded (``change``) has
    :func:`l1_bounded_change` over its bound in place of its l1 norm."""
    keep = W > 0
    W = W[keep]
    dW = np.full(len(W), np.inf) if change is None else np.asarray(change, float)[keep]
    A_c = np.mean([A for A, _ in blocks], axis=0)
    B_c = np.mean([B[:, keep] for _, B in blocks], axis=0)

    def fixed():  # rho fixed (one block, or the two ends the same): the l1 norms alone
        L1 = l1_norms(A_c, B_c, rows)
        if L1 is not None:
            _bounded_change(L1, A_c, B_c, rows, W, dW)
        return None if L1 is None else (keep, W, L1, None)

    if len(blocks) == 1:
        return fixed()
    (A0, B0), (A1, B1) = blocks
    span = rhos[1] - rhos[0]
    D = np.hstack([A1 - A0, (B1 - B0)[:, keep]]) / span
    U, S, Vt = np.linalg.svd(D)
    if S[0] == 0:
        return fixed()
    if S[1] > 1e-9 * S[0]:  # not rank one: no scalar small gain here
        return None
    n = A_c.shape[0]
    u, v, vs = U[:, 0], Vt[0, :n], Vt[0, n:]
    g = 0.5 * span * S[0]
    L1 = l1_norms(A_c, np.column_stack([B_c, u]), np.vstack([rows, v]))
    if L1 is None:
        return None
    _bounded_change(L1, A_c, B_c, np.vstack([rows, v]), W, dW)
    gain = g * L1[-1, -1]
    if not gain < 1:
        return None
    return keep, W, L1, (g, vs, gain)


def _bounded_change(L1, A, B, rows, W, dW) -> None:
    """Replace, in place, the l1 norm of every column whose input's change is bounded
    (``dW`` finite) by :func:`l1_bounded_change` over its bound, where smaller; only on
    the rows where that column is at least :data:`_WORTH` of the row's bound (elsewhere
    the gain is small and the dual's cost is not)."""
    share = L1[: len(rows), : len(W)] * W
    total = share.sum(axis=1)
    for c in np.flatnonzero(np.isfinite(dW) & (dW <= _SLOW_CHANGE * W)):
        pick = np.flatnonzero(share[:, c] >= _WORTH * total)
        if len(pick) == 0:
            continue
        got = _dual_cached(A, B[:, c], rows[pick], float(W[c]), float(dW[c]), L1[pick, c] * W[c])
        if got is not None:
            ok = np.isfinite(got)
            L1[pick[ok], c] = np.minimum(L1[pick[ok], c], got[ok] / W[c])


_MEMO: dict[bytes, np.ndarray | None] = {}


def _dual_cached(A, b, rows, bound, change, plain):
    """:func:`_dual_bound`, remembered for the same arguments (the certificate asks
    for each plant's once per cover of the reference; the result is a pure function)."""
    key = hashlib.sha256(
        b"".join(
            np.ascontiguousarray(x, float).tobytes() for x in (A, b, rows, [bound, change], plain)
        )
        + repr((A.shape, rows.shape)).encode()
    ).digest()
    if key not in _MEMO:
        if len(_MEMO) >= 1024:
            _MEMO.clear()
        _MEMO[key] = _dual_bound(A, b, rows, bound, change, plain)
    out = _MEMO[key]
    return None if out is None else out.copy()
