"""The synthesis programs: observer gains from the sector, sampled, lumped, robust,
Theorem 1 and lipschitz LMIs.

Conventions: see the package docstring (:mod:`bwdesign.certify.lmi`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import cvxpy as cp
import numpy as np

from .core import E3, I3, LMISolution, Program, cached_program, run_program, solve, sym

__all__ = [
    "REFINE_P_WEIGHT",
    "sector_synthesis",
    "sampled_synthesis",
    "lumped_sampled_synthesis",
    "robust_observer_synthesis",
    "theorem1_synthesis",
    "lipschitz_synthesis",
]

#: Weight of ``||P||_F^2`` next to ``||Y||^2`` in the refinement objective.
REFINE_P_WEIGHT = 1e-2


def _objective(
    t: cp.Variable, P: cp.Variable, Y: cp.Variable, params: dict[str, cp.Parameter], refine: bool
) -> tuple[Any, list[Any]]:
    """Maximise the margin, or (refine) keep ``t >= t_min`` and minimise the gains.

    The refinement objective ``||Y||^2 + w ||P||_F^2`` is strictly convex, so the
    refined design is unique (the max-margin face is not) and reproducible.
    """
    if not refine:
        return cp.Maximize(t), []
    t_min = cp.Parameter(nonneg=True, name="t_min")
    params["t_min"] = t_min
    obj = cp.Minimize(cp.sum_squares(Y) + REFINE_P_WEIGHT * cp.sum_squares(P))
    return obj, [t >= t_min]


def _build_sector_synthesis(with_disk: bool, refine: bool = False) -> Callable[[], Program]:
    def build() -> Program:
        A0 = cp.Parameter((3, 3), name="A0")
        C = cp.Parameter((1, 3), name="C")
        k = [cp.Parameter(name=f"k{i}") for i in range(2)]
        mu = cp.Parameter(nonneg=True, name="mu")
        params = {"A0": A0, "C": C, "k0": k[0], "k1": k[1], "mu": mu}
        P = cp.Variable((3, 3), symmetric=True, name="P")
        Y = cp.Variable((3, 1), name="Y")
        t = cp.Variable(name="t")
        PA = P @ A0 - Y @ C  # P (A0 - l C) with Y = P l
        PE = P @ (E3 @ E3.T)
        cons = [P >> t * I3, P << I3]
        for ki in k:
            M = PA + PA.T - ki * (PE + PE.T) + 2 * mu * P
            cons.append(sym(M) << -t * I3)
        if with_disk:
            R = cp.Parameter(nonneg=True, name="R")
            params["R"] = R
            D = cp.bmat([[-R * P, PA], [PA.T, -R * P]])
            cons.append(sym(D) << -t * np.eye(6))
        obj, extra = _objective(t, P, Y, params, refine)
        prob = cp.Problem(obj, cons + extra)
        return Program(prob, params, {"P": P, "Y": Y, "t": t})

    return build


def sector_synthesis(
    A0: np.ndarray,
    C: np.ndarray,
    *,
    k_lo: float,
    k_hi: float,
    mu: float = 0.0,
    radius: float | None = None,
    t_min: float | None = None,
) -> LMISolution:
    """Gains ``l = P^-1 Y`` making the sector LMI hold, with an optional pole disk.

    Maximises ``t`` subject to ``He(P A0 - Y C - k P e3 e3' + mu P) <= -t I`` at
    both sector ends, ``t I <= P <= I`` and, when ``radius`` is given,
    ``[[-R P, P A], [A' P, -R P]] <= -t I`` (eigenvalues of ``A = A0 - l C`` in
    the disk ``|s| < R``). With ``t_min`` it instead keeps ``t >= t_min`` and
    minimises ``||Y||^2 + w ||P||_F^2`` (the refinement stage: the smallest
    gains with that margin, a unique point).
    """
    refine = t_min is not None
    key = f"sector_synthesis_disk{radius is not None}_refine{refine}"
    prog = cached_program(key, _build_sector_synthesis(radius is not None, refine))
    values: dict[str, Any] = {
        "A0": np.asarray(A0, float),
        "C": np.asarray(C, float).reshape(1, 3),
        "k0": float(k_lo),
        "k1": float(k_hi),
        "mu": float(mu),
    }
    if radius is not None:
        values["R"] = float(radius)
    if refine:
        values["t_min"] = float(t_min)
    return run_program(prog, values, first_only=True)


def _build_sampled_synthesis(with_disk: bool, refine: bool = False) -> Callable[[], Program]:
    def build() -> Program:
        FR = [cp.Parameter((3, 3), name=f"FR{i}") for i in range(2)]
        HR = [cp.Parameter((1, 3), name=f"HR{i}") for i in range(2)]
        r2 = cp.Parameter(nonneg=True, name="r2")
        params = {"FR0": FR[0], "FR1": FR[1], "HR0": HR[0], "HR1": HR[1], "r2": r2}
        P = cp.Variable((3, 3), symmetric=True, name="P")
        Y = cp.Variable((3, 1), name="Y")
        t = cp.Variable(name="t")
        cons = [P >> t * I3, P << I3]
        for F_i, H_i in zip(FR, HR, strict=True):
            PA = P @ F_i - Y @ H_i  # P (I - K C) F R(rho) with Y = P K
            M = cp.bmat([[r2 * P, PA.T], [PA, P]])
            cons.append(sym(M) >> t * np.eye(6))
        if with_disk:
            F = cp.Parameter((3, 3), name="F")
            H = cp.Parameter((1, 3), name="H")
            c = cp.Parameter(name="c")
            rho = cp.Parameter(nonneg=True, name="rho")
            params.update({"F": F, "H": H, "c": c, "rho": rho})
            PM = P @ F - Y @ H - c * P
            D = cp.bmat([[rho * P, PM.T], [PM, rho * P]])
            cons.append(sym(D) >> t * np.eye(6))
        obj, extra = _objective(t, P, Y, params, refine)
        prob = cp.Problem(obj, cons + extra)
        return Program(prob, params, {"P": P, "Y": Y, "t": t})

    return build


def sampled_synthesis(
    F: np.ndarray,
    H: np.ndarray,
    *,
    rho_lo: float,
    rho_hi: float,
    r: float,
    disk: tuple[float, float] | None = None,
    t_min: float | None = None,
) -> LMISolution:
    """Discrete gains ``K = P^-1 Y`` for ``eps+ = (I - K C) F diag(1, 1, rho) eps``.

    Maximises ``t`` subject to ``[[r^2 P, A_i' P], [P A_i, P]] >= t I`` at
    ``rho in {rho_lo, rho_hi}`` with ``P A_i = (P F - Y H) diag(1, 1, rho_i)``,
    ``t I <= P <= I`` and, when ``disk = (c, radius)`` is given, the nominal
    poles ``eig(F - K H)`` in the disk ``|z - c| < radius``. With ``t_min``:
    the refinement stage, as in :func:`sector_synthesis`.

    Parameters
    ----------
    F : ndarray, shape (3, 3)
        Scaled one-sample transition of the model copy.
    H : ndarray, shape (1, 3)
        Scaled ``C F`` (the measurement seen through one sample).
    """
    F = np.asarray(F, float)
    H = np.asarray(H, float).reshape(1, 3)
    refine = t_min is not None
    key = f"sampled_synthesis_disk{disk is not None}_refine{refine}"
    prog = cached_program(key, _build_sampled_synthesis(disk is not None, refine))
    values: dict[str, Any] = {"r2": float(r) ** 2}
    for i, rho in enumerate((rho_lo, rho_hi)):
        R = np.diag([1.0, 1.0, float(rho)])
        values[f"FR{i}"] = F @ R
        values[f"HR{i}"] = H @ R
    if disk is not None:
        values.update({"F": F, "H": H, "c": float(disk[0]), "rho": float(disk[1])})
    if refine:
        values["t_min"] = float(t_min)
    return run_program(prog, values, first_only=True)


def lumped_sampled_synthesis(
    F: np.ndarray, h: np.ndarray, J: np.ndarray | None, *, r: float
) -> LMISolution:
    """Discrete gains for the disturbance observer's observable part (``l3 = 0`` split).

    Variables ``P_o`` (3x3), ``p``, ``Y = P_o K_o`` and the margin ``t``; with
    ``P_o Phi_o = P_o F - Y h'`` (``h' = C F``) every block is affine in them:

    - nominal decay (``rho = 1``): ``[[r^2 P_o - t I, (P_o Phi_o)'], [P_o Phi_o, P_o]] >= 0``;
    - the contracting vertex ``A_d = blockdiag(Phi_o, 1) J``:
      ``[[P - t I, (blockdiag(P_o Phi_o, p) J)'], [blockdiag(P_o Phi_o, p) J, P]] >= 0``
      (``J = None``: no such vertex);
    - ``t I <= P_o <= I``, ``t <= p <= 1``. Maximises ``t``; ``K_o = P_o^-1 Y``.
    """
    F = np.asarray(F, float)
    h = np.asarray(h, float).reshape(1, 3)
    Po = cp.Variable((3, 3), symmetric=True, name="Po")
    p = cp.Variable(name="p")
    Y = cp.Variable((3, 1), name="Y")
    t = cp.Variable(name="t")
    PoPhi = Po @ F - Y @ h
    cons = [Po >> t * I3, Po << I3, p >= t, p <= 1]
    M = cp.bmat([[float(r) ** 2 * Po - t * I3, PoPhi.T], [PoPhi, Po]])
    cons.append(sym(M) >> 0)
    if J is not None:
        z31 = np.zeros((3, 1))
        pp = cp.reshape(p, (1, 1), order="C")
        P = cp.bmat([[Po, z31], [z31.T, pp]])
        PA = cp.bmat([[PoPhi, z31], [z31.T, pp]]) @ np.asarray(J, float)
        M4 = cp.bmat([[P - t * np.eye(4), PA.T], [PA, P]])
        cons.append(sym(M4) >> 0)
    prob = cp.Problem(cp.Maximize(t), cons)
    return solve(prob, {"Po": Po, "p": p, "Y": Y, "t": t})


def _build_robust_observer(m_w: int, noisy: bool, k: int, disk: bool) -> Program:
    """The program of :func:`robust_observer_synthesis` for ``m_w`` inputs (and the noise
    when ``noisy``), ``k`` slopes and with or without the pole disk, every number a
    parameter: the contraction search solves it a dozen times on the same data."""
    m = m_w + int(noisy)
    FD = [cp.Parameter((3, 3), name=f"FD{i}") for i in range(k)]
    Bw = cp.Parameter((3, m_w), name="Bw")
    F = cp.Parameter((3, 3), name="F")
    cc = cp.Parameter((3, 1), name="c")
    a = cp.Parameter(nonneg=True, name="a")
    noise = cp.Parameter(nonneg=True, name="noise")
    eps = cp.Parameter(nonneg=True, name="eps")
    centre = cp.Parameter(name="centre")
    radius = cp.Parameter(nonneg=True, name="radius")
    P, Y = cp.Variable((3, 3), symmetric=True, name="P"), cp.Variable((3, 1), name="Y")
    lam, g = cp.Variable(m, nonneg=True, name="lam"), cp.Variable(name="g")
    C = np.array([[1.0, 0.0, 0.0]])
    PB = P @ Bw - Y @ (C @ Bw)
    if noisy:
        PB = cp.hstack([PB, noise * Y])
    epi = cp.bmat([[cp.reshape(g, (1, 1), order="C"), cc.T], [cc, P]])
    cons = [P >> eps * I3, cp.sum(lam) <= 1.0, sym(epi) >> 0]
    for D in FD:  # G F D_i = P (F D_i) - Y (C F D_i)
        PA = P @ D - Y @ (C @ D)
        Z = np.zeros((3, m))
        M = cp.bmat([[a * P, Z, PA.T], [Z.T, (1 - a) * cp.diag(lam), PB.T], [PA, PB, P]])
        cons.append(sym(M) >> eps * np.eye(6 + m))
    if disk:
        PM = P @ F - Y @ (C @ F) - centre * P
        cons.append(sym(cp.bmat([[radius * P, PM.T], [PM, radius * P]])) >> eps * np.eye(6))
    params = {p.name(): p for p in [*FD, Bw, F, cc, a, noise, eps, centre, radius]}
    variables = {"P": P, "Y": Y, "lam": lam, "g": g}
    return Program(cp.Problem(cp.Minimize(g), cons), params, variables)


def robust_observer_synthesis(
    F: np.ndarray,
    Bw: np.ndarray,
    c: np.ndarray,
    *,
    rho: tuple[float, float],
    a: float,
    noise: float,
    disk: tuple[float, float] | None = None,
    eps: float = 1e-7,
) -> LMISolution:
    """Gain ``K = P^-1 Y`` minimising the peak of ``c'e``, ``e+ = (I - K C)(F D_i e + Bw w) + K n``.

    ``C = e1'``, ``D_i = diag(1, 1, rho_i)``, ``V = e'Pe``, inputs normalised (``n`` by
    ``noise``). With ``Y = P K``, ``G = P - Y C``: ``[[a P, 0, (G F D_i)'], [0, (1-a)
    diag(lam), (PB)'], [G F D_i, PB, P]] >= eps I`` with ``PB = [G Bw, noise Y]``,
    ``sum(lam) <= 1``, ``P >= eps I``, optionally the nominal poles in the disk ``disk =
    (centre, r)`` (``[[r P, M'], [M, r P]] >= eps I``, ``M = G F - centre P``); minimises
    ``g >= c'P^-1 c`` (Schur), the squared peak of ``c'e`` on ``{e'Pe <= 1}``. Clarabel runs
    without chordal decomposition (with it, these programs failed often). The program is
    built once per thread and shape (:func:`~.core.cached_program`).
    """
    F, Bw, cc = np.asarray(F, float), np.asarray(Bw, float), np.asarray(c, float).reshape(3, 1)
    noisy = noise > 0
    k, m_w = len(rho), Bw.shape[1]
    key = f"robust_observer/{m_w}/{int(noisy)}/{k}/{int(disk is not None)}"
    prog = cached_program(key, lambda: _build_robust_observer(m_w, noisy, k, disk is not None))
    values: dict[str, Any] = {
        "Bw": Bw, "F": F, "c": cc, "a": float(a), "noise": float(noise) if noisy else 0.0,
        "eps": float(eps), "centre": float(disk[0]) if disk else 0.0,
        "radius": float(disk[1]) if disk else 0.0,
    }  # fmt: skip
    for i, r in enumerate(rho):
        values[f"FD{i}"] = F @ np.diag([1.0, 1.0, float(r)])
    opts = {"chordal_decomposition_enable": False}
    return run_program(prog, values, first_only=True, options=opts)


def _disk(X: Any, XA: Any, r: Any, t: Any = 0.0) -> list[Any]:
    """``[[-r X, X A], [A' X, -r X]] <= -t I``: the eigenvalues of ``A`` in ``|s| < r``."""
    return [] if r is None else [sym(cp.bmat([[-r * X, XA], [XA.T, -r * X]])) << -t * np.eye(6)]


def _scaled_params(with_disk: bool) -> dict[str, cp.Parameter]:
    """The parameters the Theorem 1 and lipschitz programs share (scaled coordinates)."""
    params = {
        "Ahat": cp.Parameter((3, 3), name="Ahat"),
        "mu": cp.Parameter(nonneg=True, name="mu"),
        "lmax": cp.Parameter(nonneg=True, name="lmax"),
    }
    if with_disk:
        params["radius"] = cp.Parameter(nonneg=True, name="radius")
    return params


def _scaled_values(Ahat: np.ndarray, mu: float, lmax: float, radius: float | None) -> dict:
    values: dict[str, Any] = {
        "Ahat": np.asarray(Ahat, float).reshape(3, 3),
        "mu": float(mu),
        "lmax": float(lmax),
    }
    if radius is not None:
        values["radius"] = float(radius)
    return values


def _build_theorem1(with_disk: bool) -> Callable[[], Program]:
    def build() -> Program:
        params = _scaled_params(with_disk)
        X = cp.Variable((3, 3), symmetric=True, name="X")
        Z = cp.Variable((3, 1), name="Z")
        p = cp.Variable(name="p")
        XA = X @ params["Ahat"] - Z @ np.array([[1.0, 0.0, 0.0]])
        He = XA + XA.T + 2 * params["mu"] * X
        cons = [X >> (p / 100.0) * I3, X << p * I3, sym(He) << -I3]
        cons += [cp.norm(Z) <= params["lmax"] * p]
        cons += _disk(X, XA, params.get("radius"))
        prob = cp.Problem(cp.Minimize(p), cons)
        return Program(prob, params, {"X": X, "Z": Z, "p": p})

    return build


def theorem1_synthesis(
    Ahat: np.ndarray, *, mu: float, lmax: float, radius: float | None = None
) -> LMISolution:
    """Gains for Theorem 1 (sign corrected) in scaled coordinates: least ``||X||``.

    ``He(X Ahat - Z e1') + 2 mu X <= -I``, ``p/100 I <= X <= p I``, ``||Z|| <= lmax p``
    (so the scaled gain ``||X^-1 Z|| <= 100 lmax``), and with ``radius`` the poles of
    ``Ahat - X^-1 Z e1'`` in ``|s| <= radius`` (:func:`_disk`); minimises ``p`` (then
    ``l = X^-1 Z``). Variables ``X`` (3 x 3), ``Z`` (3,), ``p``. A parametrised
    program, compiled once per thread and disk choice.
    """
    disk = radius is not None
    prog = cached_program(f"theorem1_synthesis_disk{disk}", _build_theorem1(disk))
    return run_program(prog, _scaled_values(Ahat, mu, lmax, radius))


def _build_lipschitz(with_disk: bool) -> Callable[[], Program]:
    def build() -> Program:
        params = _scaled_params(with_disk)
        params["L2"] = cp.Parameter(nonneg=True, name="L2")
        X = cp.Variable((3, 3), symmetric=True, name="X")
        Z = cp.Variable((3, 1), name="Z")
        t = cp.Variable(name="t")
        p = cp.Variable(name="p")
        XA = X @ params["Ahat"] - Z @ np.array([[1.0, 0.0, 0.0]])
        He = XA + XA.T + 2 * params["mu"] * X + params["L2"] * (E3 @ E3.T)
        corner = cp.reshape(t - 1, (1, 1), order="C")
        M = cp.bmat([[He + t * I3, X @ E3], [E3.T @ X, corner]])
        cons = [X >> I3, X << p * I3, cp.norm(Z) <= params["lmax"] * p, sym(M) << 0, t <= 1.0]
        cons += _disk(X, XA, params.get("radius"), t)
        prob = cp.Problem(cp.Maximize(t), cons)
        return Program(prob, params, {"X": X, "Z": Z, "t": t})

    return build


def lipschitz_synthesis(
    Ahat: np.ndarray, *, L: float, mu: float, lmax: float, radius: float | None = None
) -> LMISolution:
    """Feasibility of the lipschitz S-procedure LMI in ``(X, Z = X l)`` (scaled coordinates).

    ``[[He(X Ahat - Z e1') + 2 mu X + L^2 e3 e3' + t I, X e3], [e3' X, -1 + t]] <= 0``,
    ``I <= X <= p I``, ``||Z|| <= lmax p``, with ``radius`` the pole disk with margin
    ``t`` (:func:`_disk`); maximises the margin ``t`` (certified when ``t > 0``).
    A parametrised program, compiled once per thread and disk choice: the
    synthesis bisects on ``L`` and re-solves it with new values only.

    Clarabel only (``first_only``): the synthesis bisects on ``L`` and takes an
    unsolved program for an infeasible one. Where Clarabel stops short of
    ``OPTIMAL`` here (beyond the largest ``L`` it solves, the margin jumps from
    about 0.8 to an inaccurate solve) the SCS fall-back never returned ``OPTIMAL``
    on the bundled stages either (16 of 39 bisection steps), and cost about 1 s each.
    """
    disk = radius is not None
    prog = cached_program(f"lipschitz_synthesis_disk{disk}", _build_lipschitz(disk))
    values = _scaled_values(Ahat, mu, lmax, radius)
    values["L2"] = float(L) ** 2
    return run_program(prog, values, first_only=True)
