"""The certificate programs: margins of the tiers, the least-norm Lyapunov matrix, the
disturbance observer's lumped error and the robust invariant ellipsoid.

Conventions: see the package docstring (:mod:`bwdesign.certify.lmi`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import cvxpy as cp
import numpy as np

from .core import E3, I3, LMISolution, Program, cached_program, run_program, solve, sym

__all__ = [
    "lipschitz_margin",
    "sector_margin",
    "sampled_margin",
    "sampled_delta_margin",
    "least_norm_lyapunov",
    "lumped_margin",
    "robust_ellipsoid",
]


def _build_lipschitz() -> Program:
    A = cp.Parameter((3, 3), name="A")
    L2 = cp.Parameter(nonneg=True, name="L2")
    mu = cp.Parameter(nonneg=True, name="mu")
    P = cp.Variable((3, 3), symmetric=True, name="P")
    t = cp.Variable(name="t")
    top = A.T @ P + P @ A + 2 * mu * P + L2 * (E3 @ E3.T)
    Pe3 = P @ E3
    M = cp.bmat([[top, Pe3], [Pe3.T, -np.ones((1, 1))]])
    cons = [sym(M) << -t * np.eye(4), P >> t * I3]
    prob = cp.Problem(cp.Maximize(t), cons)
    return Program(prob, {"A": A, "L2": L2, "mu": mu}, {"P": P, "t": t})


def lipschitz_margin(A: np.ndarray, *, L: float, mu: float = 0.0) -> LMISolution:
    """S-procedure (bounded-real) LMI for ``|phi| <= L |eps3|``.

    Maximises ``t`` subject to
    ``[[A'P + PA + 2 mu P + L^2 e3 e3', P e3], [e3' P, -1]] <= -t I`` and
    ``P >= t I``.

    Parameters
    ----------
    A : ndarray, shape (3, 3)
        Scaled error-dynamics matrix.
    L : float
        Scaled Lipschitz constant (>= 0).
    mu : float
        Scaled decay rate (>= 0).
    """
    prog = cached_program("lipschitz", _build_lipschitz)
    return run_program(prog, {"A": np.asarray(A, float), "L2": float(L) ** 2, "mu": float(mu)})


def _build_sector() -> Program:
    A = cp.Parameter((3, 3), name="A")
    k = [cp.Parameter(name=f"k{i}") for i in range(2)]
    mu = cp.Parameter(nonneg=True, name="mu")
    P = cp.Variable((3, 3), symmetric=True, name="P")
    t = cp.Variable(name="t")
    PE = P @ (E3 @ E3.T)
    cons = [P >> t * I3, P << I3]
    for ki in k:
        M = A.T @ P + P @ A - ki * (PE + PE.T) + 2 * mu * P
        cons.append(sym(M) << -t * I3)
    prob = cp.Problem(cp.Maximize(t), cons)
    return Program(prob, {"A": A, "k0": k[0], "k1": k[1], "mu": mu}, {"P": P, "t": t})


def sector_margin(A: np.ndarray, *, k_lo: float, k_hi: float, mu: float = 0.0) -> LMISolution:
    """Common quadratic Lyapunov function for ``A - k e3 e3'`` at both sector ends.

    Maximises ``t`` subject to ``He(P (A - k e3 e3' + mu I)) <= -t I`` for
    ``k in {k_lo, k_hi}``, ``t I <= P <= I``. The LMI is affine in ``k``, so it
    then holds on the whole interval.
    """
    prog = cached_program("sector", _build_sector)
    return run_program(
        prog,
        {"A": np.asarray(A, float), "k0": float(k_lo), "k1": float(k_hi), "mu": float(mu)},
    )


def _build_sampled() -> Program:
    Ad = [cp.Parameter((3, 3), name=f"Ad{i}") for i in range(2)]
    r2 = cp.Parameter(nonneg=True, name="r2")
    P = cp.Variable((3, 3), symmetric=True, name="P")
    t = cp.Variable(name="t")
    cons = [P >> t * I3, P << I3]
    for A in Ad:
        PA = P @ A
        M = cp.bmat([[r2 * P, PA.T], [PA, P]])
        cons.append(sym(M) >> t * np.eye(6))
    prob = cp.Problem(cp.Maximize(t), cons)
    return Program(prob, {"Ad0": Ad[0], "Ad1": Ad[1], "r2": r2}, {"P": P, "t": t})


def sampled_margin(Ad_lo: np.ndarray, Ad_hi: np.ndarray, *, r: float) -> LMISolution:
    """Discrete polytopic LMI ``A_i' P A_i <= r^2 P`` at both vertices (Schur form).

    Maximises ``t`` subject to ``[[r^2 P, A_i' P], [P A_i, P]] >= t I`` for both
    vertices and ``t I <= P <= I``.
    """
    prog = cached_program("sampled", _build_sampled)
    return run_program(
        prog,
        {"Ad0": np.asarray(Ad_lo, float), "Ad1": np.asarray(Ad_hi, float), "r2": float(r) ** 2},
    )


def _build_sampled_delta() -> Program:
    D = [cp.Parameter((3, 3), name=f"D{i}") for i in range(2)]
    sh = cp.Parameter(nonneg=True, name="sh")
    c = cp.Parameter(nonneg=True, name="c")
    P = cp.Variable((3, 3), symmetric=True, name="P")
    t = cp.Variable(name="t")
    cons = [P >> t * I3, P << I3]
    for Di in D:
        PD = P @ Di
        M = cp.bmat([[PD + PD.T + c * P, sh * PD.T], [sh * PD, -P]])
        cons.append(sym(M) << -t * np.eye(6))
    prob = cp.Problem(cp.Maximize(t), cons)
    return Program(prob, {"D0": D[0], "D1": D[1], "sh": sh, "c": c}, {"P": P, "t": t})


def sampled_delta_margin(D_lo: np.ndarray, D_hi: np.ndarray, *, h: float, c: float) -> LMISolution:
    """The sampled LMI in delta form, well conditioned for small sample times.

    With ``A_d = I + h D`` (scaled time), ``A_d' P A_d - r^2 P < 0`` divided by
    ``h`` is ``He(P D) + c P + h D' P D < 0`` (``c = (1 - r^2)/h``); its Schur
    complement form ``[[He(P D) + c P, sqrt(h) D' P], [sqrt(h) P D, -P]] <= -t I``
    is solved at both vertices with ``t I <= P <= I``, maximising ``t``.

    Parameters
    ----------
    D_lo, D_hi : ndarray, shape (3, 3)
        Scaled delta-form matrices at the two ends.
    h : float
        Scaled sample time (``sqrt(a1) dt``).
    c : float
        Scaled ``(1 - r^2)/dt``.
    """
    prog = cached_program("sampled_delta", _build_sampled_delta)
    return run_program(
        prog,
        {
            "D0": np.asarray(D_lo, float),
            "D1": np.asarray(D_hi, float),
            "sh": float(np.sqrt(h)),
            "c": float(c),
        },
    )


_SYM_INDEX = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _build_least_norm() -> Program:
    B = [cp.Parameter((3, 3), symmetric=True, name=f"B{i}{j}") for i, j in _SYM_INDEX]
    Q = cp.Variable((3, 3), symmetric=True, name="Q")
    tau = cp.Variable(name="tau")
    P = sum(Q[i, j] * Bk for (i, j), Bk in zip(_SYM_INDEX, B, strict=True))
    cons = [Q >> I3, sym(P) << tau * I3]
    prob = cp.Problem(cp.Minimize(tau), cons)
    params = {f"B{i}{j}": Bk for (i, j), Bk in zip(_SYM_INDEX, B, strict=True)}
    return Program(prob, params, {"Q": Q, "tau": tau})


def least_norm_lyapunov(basis: Mapping[tuple[int, int], np.ndarray]) -> LMISolution:
    """Least ``tau`` with ``A'P + PA <= -I`` and ``P <= tau I``, parametrised by ``Q``.

    The Lyapunov operator is a bijection, so ``{P : A'P + PA <= -I}`` is
    ``{P(Q) : Q >= I}`` with ``P(Q)`` the solution of ``A'P + PA = -Q``. The
    program is written in ``Q`` (which is well conditioned even when ``P`` is
    not) with ``P(Q) = sum_ij Q_ij B_ij``.

    Parameters
    ----------
    basis : mapping of (i, j) to ndarray, shape (3, 3)
        ``B_ij`` for ``(i, j)`` in ``(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)``:
        the solution of ``A'P + PA = -E_ij`` where ``E_ij`` has ones at
        ``(i, j)`` and ``(j, i)``; for ``i != j`` pass the solution for that
        symmetric pair (``Q_ij`` multiplies it once). Normalise it so that its
        norms are of order one.
    """
    prog = cached_program("least_norm", _build_least_norm)
    values = {}
    for i, j in _SYM_INDEX:
        Bk = np.asarray(basis[(i, j)], float)
        values[f"B{i}{j}"] = (Bk + Bk.T) / 2
    return run_program(prog, values)


# -- the disturbance observer's lumped error (bwdesign.certify.disturbance) ----------


def _lumped_problem(
    A_o: np.ndarray, vertices: list[np.ndarray], *, discrete: bool
) -> tuple[cp.Problem, dict[str, cp.Variable]]:
    """``P = blockdiag(P_o, p)`` with a margin ``t`` on the observable block and the vertices.

    Continuous: ``He(P_o A_o) <= -t I`` and ``He(P A_i) <= -t I``; discrete (Schur
    form): ``A_o' P_o A_o <= P_o - t I`` and ``A_i' P A_i <= P - t I``; ``t <= p``,
    ``t I <= P_o <= I``, ``p <= 1``.
    """
    Po = cp.Variable((3, 3), symmetric=True, name="Po")
    p = cp.Variable(name="p")
    t = cp.Variable(name="t")
    P = cp.bmat([[Po, np.zeros((3, 1))], [np.zeros((1, 3)), cp.reshape(p, (1, 1), order="C")]])
    cons = [Po >> t * I3, Po << I3, p >= t, p <= 1]

    def neg(Pm, A, n):
        if discrete:
            PA = Pm @ A
            M = cp.bmat([[Pm - t * np.eye(n), PA.T], [PA, Pm]])
            return sym(M) >> 0
        PA = Pm @ A
        return sym(PA + PA.T) << -t * np.eye(n)

    if A_o is not None:
        cons.append(neg(Po, np.asarray(A_o, float), 3))
    for A in vertices:
        cons.append(neg(P, np.asarray(A, float), 4))
    return cp.Problem(cp.Maximize(t), cons), {"Po": Po, "p": p, "t": t}


def lumped_margin(
    A_o: np.ndarray | None, vertices: list[np.ndarray], *, discrete: bool
) -> LMISolution:
    """A block-diagonal Lyapunov function for the disturbance observer's error.

    In the coordinates ``(e1, e2, ew, eta)`` (scaled) the error matrix at the
    degenerate vertex (hysteresis not contracting: sector ``k = 0`` or jump slope
    ``rho = 1``) is ``blockdiag(A_o, 0)`` (continuous) or ``blockdiag(A_o, 1)``
    (discrete): only its observable block ``A_o`` is constrained there. The other
    vertices ``A_i`` (4x4) are constrained in full. Maximises the margin ``t``
    (see the module conventions); ``A_o = None`` when no vertex is degenerate.
    """
    prob, variables = _lumped_problem(A_o, list(vertices), discrete=discrete)
    return solve(prob, variables)


# -- robust invariant ellipsoid (bwdesign.certify.robust) ----------------------


#: A robust-ellipsoid program of at most this many block entries (``k n (n + m)``) is
#: kept, per thread and shape, for the next solve (:func:`~.core.cached_program`): at 3
#: states (the observer's certificate, 2 blocks) a re-solve then costs a fifth of a fresh
#: one (4 against 20 ms). The loop's (7 states, 8 inputs) gain a tenth at best, and their
#: parameter maps would stay in memory (9 MB at 2 blocks, 240 MB at 64): built each time.
CACHED_ENTRIES = 200


def _robust_problem(As: list, Bs: list, C: Any, a: Any, eps: Any) -> tuple[cp.Problem, dict]:
    """The program of :func:`robust_ellipsoid` and its variables; ``As``, ``Bs``, ``C``
    (``c c'``), ``a`` and ``eps`` numbers or cvxpy parameters (the same program)."""
    n, m = As[0].shape[0], Bs[0].shape[1]
    Q = cp.Variable((n, n), symmetric=True, name="Q")
    lam = cp.Variable(m, nonneg=True, name="lam")
    cons = [Q >> eps * np.eye(n), cp.sum(lam) <= 1.0]
    for A, B in zip(As, Bs, strict=True):
        M = cp.bmat(
            [
                [a * Q, np.zeros((n, m)), Q @ A.T],
                [np.zeros((m, n)), (1 - a) * cp.diag(lam), B.T],
                [A @ Q, B, Q],
            ]
        )
        cons.append(sym(M) >> eps * np.eye(2 * n + m))
    return cp.Problem(cp.Minimize(cp.sum(cp.multiply(C, Q))), cons), {"Q": Q, "lam": lam}


def _build_robust(n: int, m: int, k: int) -> Program:
    """:func:`_robust_problem` for ``k`` blocks of ``n`` states and ``m`` inputs, every
    number a parameter: a contraction search solves it again and again on the same
    blocks, and canonicalising it afresh took most of the time of a small one."""
    As = [cp.Parameter((n, n), name=f"A{i}") for i in range(k)]
    Bs = [cp.Parameter((n, m), name=f"B{i}") for i in range(k)]
    a = cp.Parameter(nonneg=True, name="a")
    eps = cp.Parameter(nonneg=True, name="eps")
    C = cp.Parameter((n, n), symmetric=True, name="C")
    prob, variables = _robust_problem(As, Bs, C, a, eps)
    return Program(prob, {p.name(): p for p in [*As, *Bs, a, eps, C]}, variables)


def robust_ellipsoid(
    As: list[np.ndarray], Bs: list[np.ndarray], c: np.ndarray, *, a: float, eps: float = 1e-5
) -> LMISolution:
    """Smallest peak of ``c'z`` over a common invariant ellipsoid of ``z+ = A_i z + B_i w``.

    The ellipsoid is ``{z' Q^-1 z <= 1}``. For every ``i``:
    ``[[a Q, 0, Q A_i'], [0, (1-a) diag(lam), B_i'], [A_i Q, B_i, Q]] >= eps I``
    (the congruence by ``diag(Q, I, Q)`` of the Schur form of
    ``V(z+) <= a V(z) + (1-a) sum lam_j w_j^2``, ``V = z'Q^-1 z``), ``sum(lam) <= 1``
    (inputs normalised to ``|w_j| <= 1``) and ``Q >= eps I``; minimises ``c'Qc``, the
    squared peak of ``c'z`` on the ellipsoid (as ``<c c', Q>``). Variables ``Q``
    (n x n), ``lam`` (m,). A small program (:data:`CACHED_ENTRIES`) is built once per
    thread and shape and kept.

    The diagonal of every block holds ``(1 - a) lam_j >= eps`` for each of the ``m``
    inputs and ``sum(lam) <= 1``: unless ``1 - a >= m eps`` there is no solution, and the
    answer is ``"infeasible"`` without a solve (``solver`` ``""``). Such programs are a
    contraction search's slowest, and a solver may still call one optimal within its
    tolerance (paper_experiment, +-5 % box, PHSO: ``1 - a = 7.6e-5 < 9e-5`` "optimal"
    after 93 iterations, 7.8 s).
    """
    n = As[0].shape[0]
    m = Bs[0].shape[1]
    k = len(As)
    if not 1 - a >= m * eps:
        why = f"no solution: 1 - a = {1 - a:.3g} < {m} inputs x eps = {m * eps:.3g}"
        return LMISolution(False, "infeasible", "", None, attempts=(why,))
    As = [np.asarray(A, float) for A in As]
    Bs = [np.asarray(B, float) for B in Bs]
    cc = np.asarray(c, dtype=float).reshape(n)
    C = np.outer(cc, cc)
    opts = {"chordal_decomposition_enable": False}
    if k * n * (n + m) > CACHED_ENTRIES:
        prob, variables = _robust_problem(As, Bs, C, float(a), float(eps))
        return solve(prob, variables, first_only=True, options=opts)
    prog = cached_program(f"robust_ellipsoid/{n}/{m}/{k}", lambda: _build_robust(n, m, k))
    values: dict[str, Any] = {"a": float(a), "eps": float(eps), "C": C}
    for i, (A, B) in enumerate(zip(As, Bs, strict=True)):
        values[f"A{i}"], values[f"B{i}"] = A, B
    return run_program(prog, values, first_only=True, options=opts)
