"""Model pieces, scaling, discrete equivalents and the outside check of every LMI."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import logm, matrix_balance

from ..errors import GainError, InputError
from ..model.params import BoucWenParams
from ..model.plant import _check_dt, discretize
from ..observers.gains import _as_gains, discrete_gains
from .results import _C, _U, REL_MARGIN, Margin, _frozen

__all__ = ["continuous_equivalent", "sector_interval", "rho_interval"]


# -- model pieces ---------------------------------------------------------------


def _rate(value: float, name: str, *, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating):
        raise InputError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or (value <= 0 if positive else value < 0):
        raise InputError(
            f"{name} must be a finite number {'> 0' if positive else '>= 0'}, got {value}"
        )
    return value


def _model_matrix(params: BoucWenParams) -> np.ndarray:
    return np.array([[0.0, 1.0, 0.0], [-params.a1, -params.a2, -params.a1], [0.0, 0.0, 0.0]])


def sector_interval(params: BoucWenParams, udot_max: float) -> tuple[float, float]:
    """Interval of ``k`` in ``phi~ = -k eps3`` for ``|u'| <= udot_max`` (1/s).

    ``[min(0, (beta - |gamma|) v), max(0, (beta + |gamma|) v)]``.
    """
    g = abs(params.gamma)
    return (min(0.0, (params.beta - g) * udot_max), max(0.0, (params.beta + g) * udot_max))


def rho_interval(params: BoucWenParams, udot_max: float, dt: float) -> tuple[float, float]:
    """Interval of the hysteresis jump-map slope ``rho`` for ``|du| <= udot_max dt``.

    ``[min(1, exp(-(beta + |gamma|) v dt)), max(1, exp(-(beta - |gamma|) v dt))]``
    (dimensionless; ``inf`` when the upper end overflows).
    """
    g = abs(params.gamma)
    w = udot_max * dt
    lo = math.exp(min(0.0, -(params.beta + g) * w))
    x = max(0.0, -(params.beta - g) * w)
    hi = math.exp(x) if x < 700.0 else math.inf
    return lo, hi


def _lipschitz_coefficient(params: BoucWenParams) -> float:
    return abs(params.beta) + abs(params.gamma)


def _balance(M: np.ndarray) -> np.ndarray:
    """Diagonal balancing vector ``d`` (powers of 2) with ``d[2] = 1``."""
    try:
        _, (d, _) = matrix_balance(M, permute=False, separate=True)
    except (ValueError, np.linalg.LinAlgError):
        return np.ones(3)
    d = np.asarray(d, dtype=float)
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        return np.ones(3)
    return d / d[2]


def _similar(M: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``S^-1 M S`` for ``S = diag(s)``."""
    return M * s[None, :] / s[:, None]


@dataclass(frozen=True)
class _Scaled:
    """A continuous error matrix with its scaling ``A = w S Ahat S^-1``."""

    A: np.ndarray
    Ahat: np.ndarray
    s: np.ndarray
    w: float

    def spectral_abscissa(self, k: float = 0.0) -> float:
        Ak = self.Ahat.copy()
        Ak[2, 2] -= k / self.w
        return float(np.max(np.linalg.eigvals(Ak).real)) * self.w


def _scale_continuous(params: BoucWenParams, A: np.ndarray) -> _Scaled:
    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    AT = _similar(A, T) / w
    d = _balance(AT)
    return _Scaled(A=A, Ahat=_similar(AT, d), s=T * d, w=w)


# -- discrete gains -------------------------------------------------------------


def continuous_equivalent(
    params: BoucWenParams, K: Sequence[float], dt: float, *, rtol: float = 1e-8
) -> tuple[float, float, float] | None:
    """Continuous gains whose pole-matched discrete gain is ``K``, if they exist.

    The continuous poles are the principal logarithms of the discrete poles
    divided by ``dt`` (a real matrix logarithm of ``(I - K C) F``); they exist
    when no discrete pole lies on the closed negative real axis. The result is
    mapped back with :func:`discrete_gains` and returned only if it reproduces
    ``K`` to ``rtol`` (in scaled coordinates).

    Returns
    -------
    tuple of 3 floats or None
        ``(l1, l2, l3)``, or ``None`` when no exact equivalent exists.
    """
    dt = _check_dt(dt)
    K = np.asarray(_as_gains(K, "discrete gains K"))
    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    F = discretize(params, dt).F
    Ad = F - np.outer(K, F[0])
    Ads = _similar(Ad, T)
    z = np.linalg.eigvals(Ads)
    if np.any((np.abs(z.imag) <= 1e-12 * np.abs(z).max()) & (z.real <= 0)) or np.any(z == 0):
        return None
    try:
        Ls = logm(Ads)
    except Exception:  # noqa: BLE001 - no logarithm means no equivalent
        return None
    if np.max(np.abs(np.imag(Ls))) > 1e-9 * max(1.0, np.max(np.abs(Ls))):
        return None
    Ls = np.real(Ls) / dt
    c = np.real(np.poly(Ls))  # charpoly of the continuous A (similarity-invariant)
    a1, a2 = params.a1, params.a2
    l1 = c[1] - a2
    l2 = c[2] - a1 - l1 * a2
    l3 = -c[3] / a1
    gains = (float(l1), float(l2), float(l3))
    try:
        K2 = discrete_gains(params, gains, dt)
    except (GainError, InputError):
        return None
    if np.max(np.abs((K2 - K) / T)) > rtol * max(1.0, np.max(np.abs(K / T))):
        return None
    return gains


# -- the outside check ------------------------------------------------------------


def _negdef(name: str, M: np.ndarray, err: np.ndarray | None = None) -> Margin:
    """Margin for ``M < 0``: equilibrate by the diagonal, add a round-off bound."""
    M = (M + M.T) / 2
    dg = np.abs(np.diag(M))
    big = float(dg.max()) if dg.size and dg.max() > 0 else 1.0
    d = 1.0 / np.sqrt(np.where(dg > 0, dg, big))
    Dm = d[:, None] * d[None, :]
    Mh = M * Dm
    if not np.all(np.isfinite(Mh)):
        return Margin(name, math.inf, 0.0)
    lam = float(np.linalg.eigvalsh(Mh).max())
    norm = float(np.linalg.norm(Mh, 2))
    rounding = 8 * Mh.shape[0] * _U * norm
    if err is not None:
        rounding += float(np.linalg.norm(err * Dm, "fro"))
    return Margin(name, lam + rounding, -REL_MARGIN * norm)


def _posdef(name: str, P: np.ndarray) -> Margin:
    """Margin for ``P > 0`` (the check of ``-P < 0``)."""
    return _negdef(name, -P)


@dataclass(frozen=True)
class _Check:
    ok: bool
    P: np.ndarray | None
    margins: tuple[Margin, ...]
    solver: str
    status: str
    t: float | None = None


def _from_solution(sol: Any, what: str) -> _Check | None:
    """A failed _Check for a solver failure or a non-positive margin, else None."""
    if not sol.ok:
        tried = "; ".join(sol.attempts) or "no solver ran"
        label = "unverified" if sol.status == "optimal_inaccurate" else "solver failed"
        return _Check(
            False, None, (), sol.solver, f"{label}: {what} LMI status {sol.status} ({tried})"
        )
    t = float(sol["t"])
    if not t > 0:
        return _Check(
            False,
            None,
            (),
            sol.solver,
            f"not certified: the {what} LMI has no strictly feasible point "
            f"(margin t = {t:.3g} <= 0)",
            t,
        )
    return None


def _verdict(margins: tuple[Margin, ...], P: np.ndarray, solver: str, t: float) -> _Check:
    failed = [m.name for m in margins if not m.passed]
    if failed:
        return _Check(
            False,
            None,
            margins,
            solver,
            "not certified: the solver's P failed the outside check (" + "; ".join(failed) + ")",
            t,
        )
    return _Check(True, _frozen(P), margins, solver, "certified", t)


def _cont_err(A: np.ndarray, P: np.ndarray, mu: float) -> np.ndarray:
    aA, aP = np.abs(A), np.abs(P)
    return 16 * _U * (aA.T @ aP + aP @ aA + 2 * mu * aP)


def _check_lipschitz(sc: _Scaled, L: float, mu: float) -> _Check:
    from . import lmi

    sol = lmi.lipschitz_margin(sc.Ahat, L=L / sc.w, mu=mu / sc.w)
    bad = _from_solution(sol, "lipschitz")
    if bad is not None:
        return bad
    Ph = np.asarray(sol["P"])
    Ph = (Ph + Ph.T) / 2
    P = sc.w * Ph / np.outer(sc.s, sc.s)  # S^-T Phat S^-1, times w (s3 = 1)
    A = sc.A
    top = A.T @ P + P @ A + 2 * mu * P
    top[2, 2] += L * L
    M = np.zeros((4, 4))
    M[:3, :3] = top
    M[:3, 3] = M[3, :3] = P[:, 2]
    M[3, 3] = -1.0
    err = np.zeros((4, 4))
    err[:3, :3] = _cont_err(A, P, mu)
    err[2, 2] += 4 * _U * L * L
    margins = (
        _posdef("P > 0", P),
        _negdef("[[A'P + PA + 2 mu P + L^2 e3 e3', P e3], [e3'P, -1]] < 0", M, err),
    )
    return _verdict(margins, P, sol.solver, float(sol["t"]))


def _check_sector(sc: _Scaled, k_lo: float, k_hi: float, mu: float) -> _Check:
    from . import lmi

    sol = lmi.sector_margin(sc.Ahat, k_lo=k_lo / sc.w, k_hi=k_hi / sc.w, mu=mu / sc.w)
    bad = _from_solution(sol, "sector")
    if bad is not None:
        return bad
    Ph = np.asarray(sol["P"])
    Ph = (Ph + Ph.T) / 2
    P = Ph / np.outer(sc.s, sc.s)
    margins = [_posdef("P > 0", P)]
    for k in (k_lo, k_hi):
        Ak = sc.A.copy()
        Ak[2, 2] -= k
        M = Ak.T @ P + P @ Ak + 2 * mu * P
        margins.append(
            _negdef(f"He(P (A - k e3 e3' + mu I)) < 0 at k = {k:.6g} 1/s", M, _cont_err(Ak, P, mu))
        )
    return _verdict(tuple(margins), P, sol.solver, float(sol["t"]))


@dataclass(frozen=True)
class _Sampled:
    F: np.ndarray  # expm(A0 dt) with the x3 row [0, 0, 1]
    K: np.ndarray
    IKC_F: np.ndarray  # (I - K C) F
    s: np.ndarray
    dt: float


def _prepare_sampled(params: BoucWenParams, K: np.ndarray, dt: float) -> _Sampled:
    F = np.array(discretize(params, dt).F)
    Ad = F - np.outer(K, F[0])
    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    d = _balance(_similar(Ad, T))
    return _Sampled(F=F, K=K, IKC_F=Ad, s=T * d, dt=dt)


def _check_sampled(sp: _Sampled, rho_lo: float, rho_hi: float, r: float) -> _Check:
    from . import lmi

    if not math.isfinite(rho_hi):
        return _Check(
            False, None, (), "", "not certified: the rho interval is unbounded at this rate"
        )
    verts = []
    for rho in (rho_lo, rho_hi):
        Ad = sp.IKC_F.copy()
        Ad[:, 2] *= rho
        verts.append(Ad)
    sol = lmi.sampled_margin(_similar(verts[0], sp.s), _similar(verts[1], sp.s), r=r)
    bad = _from_solution(sol, "sampled")
    if bad is not None:
        return bad
    Ph = np.asarray(sol["P"])
    Ph = (Ph + Ph.T) / 2
    P = Ph / np.outer(sp.s, sp.s)
    margins = [_posdef("P > 0", P)]
    aIKC = np.abs(np.eye(3) - np.outer(sp.K, _C)) @ np.abs(sp.F)
    for rho, Ad in zip((rho_lo, rho_hi), verts, strict=True):
        M = Ad.T @ P @ Ad - r * r * P
        aA = aIKC * np.array([1.0, 1.0, abs(rho)])[None, :]
        err = 32 * _U * (aA.T @ np.abs(P) @ aA + r * r * np.abs(P))
        margins.append(_negdef(f"A_d' P A_d - r^2 P < 0 at rho = {rho:.6g}", M, err))
    return _verdict(tuple(margins), P, sol.solver, float(sol["t"]))
