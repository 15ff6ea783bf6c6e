"""Model pieces, scaling, discrete equivalents and the outside check of every LMI."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import logm, matrix_balance

from ..errors import GainError, InputError
from ..model.params import BoucWenParams
from ..model.plant import check_dt, discretize
from ..observers.gains import as_gains, delta_transition, discrete_gains
from .results import REL_MARGIN, UNIT_ROUNDOFF, Margin, frozen_array

__all__ = ["continuous_equivalent", "sector_interval", "rho_interval"]


# -- model pieces ---------------------------------------------------------------


def model_matrix(params: BoucWenParams) -> np.ndarray:
    """The observer's model matrix ``A0`` (state ``(x1, x2, x3)``)."""
    return np.array([[0.0, 1.0, 0.0], [-params.a1, -params.a2, -params.a1], [0.0, 0.0, 0.0]])


def sector_interval(params: BoucWenParams, udot_max: float) -> tuple[float, float]:
    """Interval of ``k`` in ``phi~ = -k eps3`` for ``|u'| <= udot_max`` (1/s).

    ``[min(0, (beta - |gamma|) v), max(0, (beta + |gamma|) v)]``.
    """
    g = abs(params.gamma)
    return (min(0.0, (params.beta - g) * udot_max), max(0.0, (params.beta + g) * udot_max))


def rho_exponents(params: BoucWenParams, udot_max: float, dt: float) -> tuple[float, float]:
    """``(ln rho_lo, ln rho_hi)`` of :func:`rho_interval`, without rounding ``rho`` first."""
    g = abs(params.gamma)
    w = udot_max * dt
    return min(0.0, -(params.beta + g) * w), max(0.0, -(params.beta - g) * w)


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


def lipschitz_coefficient(params: BoucWenParams) -> float:
    """``|beta| + |gamma|``: ``|phi~| <= (|beta| + |gamma|) |u'| |eps3|``."""
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


def similar(M: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``S^-1 M S`` for ``S = diag(s)``."""
    return M * s[None, :] / s[:, None]


@dataclass(frozen=True)
class Scaled:
    """A continuous error matrix with its scaling ``A = w S Ahat S^-1``."""

    A: np.ndarray
    Ahat: np.ndarray
    s: np.ndarray
    w: float

    def spectral_abscissa(self, k: float = 0.0) -> float:
        Ak = self.Ahat.copy()
        Ak[2, 2] -= k / self.w
        return float(np.max(np.linalg.eigvals(Ak).real)) * self.w


def scale_continuous(params: BoucWenParams, A: np.ndarray) -> Scaled:
    """``A`` in the time scale ``sqrt(a1)`` and a balancing diagonal scaling."""
    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    AT = similar(A, T) / w
    d = _balance(AT)
    return Scaled(A=A, Ahat=similar(AT, d), s=T * d, w=w)


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
    dt = check_dt(dt)
    K = np.asarray(as_gains(K, "discrete gains K"))
    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    F = discretize(params, dt).F
    Ad = F - np.outer(K, F[0])
    Ads = similar(Ad, T)
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


def negdef(name: str, M: np.ndarray, err: np.ndarray | None = None) -> Margin:
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
    rounding = 8 * Mh.shape[0] * UNIT_ROUNDOFF * norm
    if err is not None:
        rounding += float(np.linalg.norm(err * Dm, "fro"))
    return Margin(name, lam + rounding, -REL_MARGIN * norm)


def posdef(name: str, P: np.ndarray) -> Margin:
    """Margin for ``P > 0`` (the check of ``-P < 0``)."""
    return negdef(name, -P)


@dataclass(frozen=True)
class Check:
    """Outcome of one LMI tier check: the verdict, the checked ``P`` and its margins."""

    ok: bool
    P: np.ndarray | None
    margins: tuple[Margin, ...]
    solver: str
    status: str
    t: float | None = None


def _from_solution(sol: Any, what: str) -> Check | None:
    """A failed Check for a solver failure or a non-positive margin, else None."""
    if not sol.ok:
        tried = "; ".join(sol.attempts) or "no solver ran"
        label = "unverified" if sol.status == "optimal_inaccurate" else "solver failed"
        return Check(
            False, None, (), sol.solver, f"{label}: {what} LMI status {sol.status} ({tried})"
        )
    t = float(sol["t"])
    if not t > 0:
        return Check(
            False,
            None,
            (),
            sol.solver,
            f"not certified: the {what} LMI has no strictly feasible point "
            f"(margin t = {t:.3g} <= 0)",
            t,
        )
    return None


def _verdict(margins: tuple[Margin, ...], P: np.ndarray, solver: str, t: float) -> Check:
    failed = [m.name for m in margins if not m.passed]
    if failed:
        return Check(
            False,
            None,
            margins,
            solver,
            "not certified: the solver's P failed the outside check (" + "; ".join(failed) + ")",
            t,
        )
    return Check(True, frozen_array(P), margins, solver, "certified", t)


def continuous_error(A: np.ndarray, P: np.ndarray, mu: float) -> np.ndarray:
    """Entrywise round-off bound of ``A'P + PA + 2 mu P`` formed in floating point."""
    aA, aP = np.abs(A), np.abs(P)
    return 16 * UNIT_ROUNDOFF * (aA.T @ aP + aP @ aA + 2 * mu * aP)


def check_lipschitz(sc: Scaled, L: float, mu: float) -> Check:
    """The lipschitz LMI solved in scaled coordinates, then checked outside the solver."""
    from . import lmi

    sol = lmi.lipschitz_margin(sc.Ahat, L=L / sc.w, mu=mu / sc.w)
    bad = _from_solution(sol, "lipschitz")
    if bad is not None:
        return bad
    Ph = np.asarray(sol["P"])
    Ph = (Ph + Ph.T) / 2
    P = sc.w * Ph / np.outer(sc.s, sc.s)  # S^-T Phat S^-1, times w (s3 = 1)
    return verify_lipschitz(sc, L, mu, P, sol.solver, float(sol["t"]))


def verify_lipschitz(
    sc: Scaled, L: float, mu: float, P: np.ndarray, solver: str, t: float | None
) -> Check:
    """Outside check of the lipschitz LMI for a given ``P`` (original coordinates)."""
    A = sc.A
    top = A.T @ P + P @ A + 2 * mu * P
    top[2, 2] += L * L
    M = np.zeros((4, 4))
    M[:3, :3] = top
    M[:3, 3] = M[3, :3] = P[:, 2]
    M[3, 3] = -1.0
    err = np.zeros((4, 4))
    err[:3, :3] = continuous_error(A, P, mu)
    err[2, 2] += 4 * UNIT_ROUNDOFF * L * L
    margins = (
        posdef("P > 0", P),
        negdef("[[A'P + PA + 2 mu P + L^2 e3 e3', P e3], [e3'P, -1]] < 0", M, err),
    )
    return _verdict(margins, P, solver, t)


#: State weights ``eps I`` of the first Riccati candidates (scaled units).
KYP_EPS = (1e-2, 1e-4, 1e-6, 1e-9)
#: The same for the discrete Riccati equation of the sampled tier.
DARE_EPS = (1e-4, 1e-7, 1e-10)
#: Weights ``eta`` of the modal state weight ``eta gap^2 H`` (see :func:`kyp_candidates`).
KYP_MODAL = (1.0, 0.1, 1e-2, 1e-3, 1e-4, 1e-6)
#: Decay shifts of the last Riccati candidates, as fractions of ``gap``.
KYP_SHIFTS = (1e-2, 1e-4)


def modal_metric(A: np.ndarray) -> np.ndarray | None:
    """``H = T^-T T^-1`` (norm 1) for the real modal basis ``T`` of ``A``; ``None`` if defective.

    In the modal coordinates every pole's own block is a scaled rotation, so ``H`` weighs
    a lightly damped pair's plane evenly, however the original coordinates distort it.
    """
    lam, V = np.linalg.eig(A)
    cols: list[np.ndarray] = []
    used: set[int] = set()
    for i, x in enumerate(lam):
        if i in used:
            continue
        used.add(i)
        if x.imag == 0:
            cols.append(V[:, i].real)
            continue
        j = min(
            (k for k in range(len(lam)) if k not in used), key=lambda k: abs(lam[k] - x.conjugate())
        )
        used.add(j)
        cols += [V[:, i].real, V[:, i].imag]
    T = np.array(cols).T
    if T.shape != A.shape or np.linalg.cond(T) > 1e8:
        return None
    Ti = np.linalg.inv(T)
    H = Ti.T @ Ti
    return (H + H.T) / (2 * np.linalg.norm(H, 2))


def kyp_candidates(sc: Scaled, k1: float, k2: float, mu: float) -> Iterator[np.ndarray]:
    """Lyapunov matrices from the KYP Riccati equation of the sector ``[k1, k2]`` (1/s).

    The S-procedure inequality with multiplier 1,
    ``He(P A_mu) + (P e3 - s e3)(e3' P - s e3') - k1 k2 e3 e3' < 0`` with
    ``s = (k1 + k2)/2``, holds with ``-W`` on the right for the stabilising
    solution of the Riccati equation
    ``A_mu' P + P A_mu - (P B + S)(-1)^-1 (B' P + S') + Q = 0``, ``B = e3``,
    ``S = -s e3``, ``Q = -k1 k2 e3 e3' + W`` (scipy's
    :func:`~scipy.linalg.solve_continuous_are` with ``R = -1``), which exists when
    the circle criterion holds with room for ``W``. Solved in the scaled coordinates for

    - ``W = eps I`` (:data:`KYP_EPS`);
    - ``W = eta gap^2 H`` (:data:`KYP_MODAL`), ``H`` the :func:`modal_metric` and
      ``gap`` the distance of the poles to the line ``Re s = -mu``. For a lightly
      damped pair ``eps I`` needs ``eps`` below the squared damping (the resonance
      amplifies it) and leaves a ``P`` so ill-conditioned that round-off swamps its
      slack; the modal weight scales with the damping and keeps ``P`` even on the pair;
    - ``W = 0`` at the decay ``mu + f gap`` (:data:`KYP_SHIFTS`), slack ``2 f gap P``.

    Lazy: the caller stops at the first matrix that passes its outside check. The
    same ``P`` serves the lipschitz LMI (``k1 = -L``, ``k2 = L``) and, since the
    inequality then holds for every ``k`` in ``[k1, k2]``, the sector LMI.
    """
    w = sc.w
    A = sc.Ahat + (mu / w) * np.eye(3)
    k1h, k2h = k1 / w, k2 / w
    if not (math.isfinite(k1h) and math.isfinite(k2h)):
        return
    sh = (k1h + k2h) / 2
    B = np.array([[0.0], [0.0], [1.0]])
    Q0 = np.zeros((3, 3))
    Q0[2, 2] = -k1h * k2h
    back = np.outer(sc.s, sc.s) / w
    for eps in KYP_EPS:
        X = _care(A, B, Q0 + eps * max(1.0, abs(k1h * k2h)) * np.eye(3), sh)
        if X is not None:
            yield X / back
    gap = -float(np.max(np.linalg.eigvals(A).real))
    if not gap > 0:
        return
    H = modal_metric(A)
    for eta in KYP_MODAL if H is not None else ():
        X = _care(A, B, Q0 + eta * gap * gap * H, sh)
        if X is not None:
            yield X / back
    for frac in KYP_SHIFTS:
        X = _care(A + frac * gap * np.eye(3), B, Q0, sh)
        if X is not None:
            yield X / back


def _care(A: np.ndarray, B: np.ndarray, Q: np.ndarray, sh: float) -> np.ndarray | None:
    """The stabilising solution of the KYP Riccati equation (``R = -1``, ``S = -sh B``)."""
    from scipy.linalg import solve_continuous_are

    try:
        with np.errstate(all="ignore"):
            X = solve_continuous_are(A, B, Q, -np.ones((1, 1)), s=-sh * B)
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(X)):
        return None
    return (X + X.T) / 2


def lipschitz_candidates(P: np.ndarray, L: float) -> list[np.ndarray]:
    """Rescalings ``P / tau`` of a Theorem-1 matrix to try in the lipschitz LMI.

    If ``A'P + PA <= -q I`` and ``2 L ||P|| + 2 mu ||P|| < q``, the S-procedure
    multiplier ``tau = ||P|| / L`` makes the lipschitz LMI hold for ``P / tau``.
    """
    nP = float(np.linalg.eigvalsh((P + P.T) / 2).max())
    if not (L > 0 and nP > 0):
        return []
    tau = nP / L
    return [P / (tau * f) for f in (1.0, 2.0, 0.5, 4.0, 0.25)]


def check_sector(sc: Scaled, k_lo: float, k_hi: float, mu: float) -> Check:
    """The sector LMI solved in scaled coordinates, then checked outside the solver."""
    from . import lmi

    sol = lmi.sector_margin(sc.Ahat, k_lo=k_lo / sc.w, k_hi=k_hi / sc.w, mu=mu / sc.w)
    bad = _from_solution(sol, "sector")
    if bad is not None:
        return bad
    Ph = np.asarray(sol["P"])
    Ph = (Ph + Ph.T) / 2
    P = Ph / np.outer(sc.s, sc.s)
    return verify_sector(sc, k_lo, k_hi, mu, P, sol.solver, float(sol["t"]))


def verify_sector(
    sc: Scaled, k_lo: float, k_hi: float, mu: float, P: np.ndarray, solver: str, t: float | None
) -> Check:
    """Outside check of the sector LMI at both ends for a given ``P``."""
    margins = [posdef("P > 0", P)]
    for k in (k_lo, k_hi):
        Ak = sc.A.copy()
        Ak[2, 2] -= k
        M = Ak.T @ P + P @ Ak + 2 * mu * P
        margins.append(
            negdef(
                f"He(P (A - k e3 e3' + mu I)) < 0 at k = {k:.6g} 1/s",
                M,
                continuous_error(Ak, P, mu),
            )
        )
    return _verdict(tuple(margins), P, solver, t)


@dataclass(frozen=True)
class Sampled:
    """The sampled error dynamics ``(I - K C) F diag(1, 1, rho)`` in delta form.

    ``A_delta(rho) = Ad1 + ((rho - 1)/dt) b e3'`` with ``Ad1 = ((I - K C) F - I)/dt``
    and ``b = (I - K C) F e3``, all formed without subtracting ``I`` from a
    matrix close to ``I`` (:func:`bwdesign.observers.gains.delta_transition`).
    """

    F: np.ndarray  # expm(A0 dt) with the x3 row [0, 0, 1]
    K: np.ndarray
    IKC_F: np.ndarray  # (I - K C) F
    Ad1: np.ndarray  # ((I - K C) F - I)/dt (1/s)
    b: np.ndarray  # (I - K C) F e3
    s: np.ndarray
    w: float
    dt: float

    def delta(self, x: float) -> np.ndarray:
        """``A_delta(rho)`` (1/s) at ``rho = exp(x)`` (``(rho - 1)/dt = expm1(x)/dt``, exact)."""
        return self.Ad1 + (math.expm1(x) / self.dt) * np.outer(self.b, _E3)

    def delta_error(self, x: float) -> np.ndarray:
        """Entrywise bound (1/s) on the error of :meth:`delta` against the exact exponential.

        ``(F - I)/dt`` comes from ``expm`` in the scaled coordinates
        ``(x1, x2/w0, x3)``, where its error is a small multiple of the unit round-off
        times the norm there (grown by ``1 + ||.|| dt`` for the squarings); ``F[0]`` is
        ``e1 + dt (F - I)[0]/dt``; ``Ad1 = (F - I)/dt - (K/dt) F[0]`` and the ``rho``
        column are rounded once more each. :func:`verify_sampled` adds the effect on
        its blocks, so a ``P`` that passes is a certificate for the exact exponential.
        """
        dt = self.dt
        T = np.array([1.0, self.w, 1.0])
        KF = np.outer(self.K / dt, self.F[0])
        Fd = self.Ad1 + KF  # (F - I)/dt
        norm_z = float(np.max(np.abs(Fd) * T[None, :] / T[:, None]))  # scaled coordinates
        E_Fd = (1.0 + norm_z * dt) * norm_z * T[:, None] / T[None, :]
        E_Fd[2] = 0.0  # the x3 row of F is exactly [0, 0, 1]
        E_F0 = np.abs(self.F[0]) + dt * E_Fd[0]
        E_Ad1 = E_Fd + np.outer(np.abs(self.K / dt), E_F0) + np.abs(Fd) + np.abs(KF)
        g = abs(math.expm1(x)) / dt if math.isfinite(x) else 1.0 / dt
        col = np.zeros((3, 3))
        col[:, 2] = g * (np.abs(self.b) + dt * E_Ad1[:, 2])
        return 64 * UNIT_ROUNDOFF * (E_Ad1 + col)


_E3 = np.array([0.0, 0.0, 1.0])


def prepare_sampled(params: BoucWenParams, K: np.ndarray, dt: float) -> Sampled:
    """The sampled error dynamics of the discrete gain ``K`` (:class:`Sampled`)."""
    F, Fd = delta_transition(params, dt)
    K = np.asarray(K, dtype=float)
    Ad = F - np.outer(K, F[0])
    Ad1 = Fd - np.outer(K / dt, F[0])
    b = _E3 + dt * Ad1[:, 2]
    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    d = _balance(similar(Ad1, T) / w)
    return Sampled(F=F, K=K, IKC_F=Ad, Ad1=Ad1, b=b, s=T * d, w=w, dt=dt)


def check_sampled(sp: Sampled, x_lo: float, x_hi: float, mu: float) -> Check:
    """The sampled LMI ``A_d' P A_d < r^2 P`` at both rho ends, solved and checked in delta form.

    Divided by ``dt`` it reads ``He(P A_delta) + dt A_delta' P A_delta + c P < 0``
    with ``c = (1 - r^2)/dt``, which stays well conditioned as ``dt -> 0``. The
    rho ends are given by their logarithms ``x = ln(rho)``.
    """
    from . import lmi

    if not x_hi < 700.0:
        return Check(
            False, None, (), "", "not certified: the rho interval is unbounded at this rate"
        )
    dt, w = sp.dt, sp.w
    c = -math.expm1(-2.0 * mu * dt) / dt
    verts = [sp.delta(x) for x in (x_lo, x_hi)]
    sol = lmi.sampled_delta_margin(
        similar(verts[0], sp.s) / w, similar(verts[1], sp.s) / w, h=w * dt, c=c / w
    )
    bad = _from_solution(sol, "sampled")
    if bad is not None:
        return bad
    Ph = np.asarray(sol["P"])
    Ph = (Ph + Ph.T) / 2
    P = Ph / np.outer(sp.s, sp.s)
    return verify_sampled(sp, x_lo, x_hi, mu, P, sol.solver, float(sol["t"]))


def verify_sampled(
    sp: Sampled,
    x_lo: float,
    x_hi: float,
    mu: float,
    P: np.ndarray,
    solver: str,
    t: float | None,
) -> Check:
    """Outside check of the delta-form sampled LMI at both rho ends for a given ``P``."""
    dt = sp.dt
    c = -math.expm1(-2.0 * mu * dt) / dt
    margins = [posdef("P > 0", P)]
    aP = np.abs(P)
    for x in (x_lo, x_hi):
        D = sp.delta(x)
        M = D.T @ P + P @ D + dt * (D.T @ P @ D) + c * P
        aD = np.abs(D)
        err = 32 * UNIT_ROUNDOFF * (aD.T @ aP + aP @ aD + dt * (aD.T @ aP @ aD) + c * aP)
        E = sp.delta_error(x)  # the exact D is within E of this one, entrywise
        EP = E.T @ aP
        err += EP + EP.T + dt * (EP @ (aD + E) + (aD + E).T @ EP.T)
        margins.append(
            negdef(
                f"(A_d' P A_d - r^2 P)/dt < 0 at rho = {math.exp(x):.6g} (delta form)",
                M,
                err,
            )
        )
    return _verdict(tuple(margins), P, solver, t)


def dare_candidates(sp: Sampled, k1: float, k2: float, mu: float) -> Iterator[np.ndarray]:
    """Lyapunov matrices of the sampled tier from the discrete KYP Riccati equation.

    ``k = (1 - rho)/dt`` in ``[k1, k2]`` (1/s); with ``A = A_d(1)/r``,
    ``b = A_d(1) e3 / r`` and ``kappa = k dt``, the S-procedure inequality
    ``[[A'PA - P - kappa1 kappa2 e3 e3', A'Pb - s e3], [., b'Pb - 1]] < 0``
    (``s = (kappa1 + kappa2)/2``) holds for the stabilising solution of
    :func:`~scipy.linalg.solve_discrete_are` with ``R = -1``, ``S = -s e3`` and
    ``Q = -kappa1 kappa2 e3 e3' + W``, when the discrete circle criterion holds. As in
    :func:`kyp_candidates`: ``W = eps I``, then ``W = eta gap^2 H`` with the modal
    metric ``H`` of ``A`` and ``gap = 1 - max |eig(A)|``, then ``W = 0`` with ``r``
    replaced by ``exp(-(mu + delta) dt)`` (slack ``(r^2 - r_delta^2) P``). Lazy.
    """
    dt = sp.dt
    c1, c2 = k1 * dt, k2 * dt
    if not (math.isfinite(c1) and math.isfinite(c2)):
        return
    sh = (c1 + c2) / 2
    As = similar(sp.IKC_F, sp.s)
    back = np.outer(sp.s, sp.s)
    Q0 = np.zeros((3, 3))
    Q0[2, 2] = -c1 * c2
    Ah = As / math.exp(-mu * dt)
    for eps in DARE_EPS:
        X = _dare(Ah, Q0 + eps * np.eye(3), sh)
        if X is not None:
            yield X / back
    lam = np.linalg.eigvals(similar(sp.Ad1, sp.s))  # delta-form poles (z - 1)/dt
    m2 = float(np.max(dt * (2.0 * lam.real + dt * np.abs(lam) ** 2)))  # max |z|^2 - 1
    if m2 > -0.5:  # poles near z = 1: their decay from the delta form, without cancellation
        nominal = -0.5 * math.log1p(m2) / dt
    else:  # poles far inside the circle (|lambda| dt >> 1): |z| itself is accurate enough
        zmax = float(np.max(np.abs(np.linalg.eigvals(As))))
        nominal = -math.log(zmax) / dt if zmax > 0 else math.inf
    gap = min(nominal - mu, 50.0 / dt)  # 1/s; beyond 50/dt nothing changes in double
    if not gap > 0:
        return
    H = modal_metric(Ah)
    gd = -math.expm1(-gap * dt)  # 1 - max |eig(Ah)|
    for eta in KYP_MODAL if H is not None else ():
        X = _dare(Ah, Q0 + eta * gd * gd * H, sh)
        if X is not None:
            yield X / back
    for frac in KYP_SHIFTS:
        X = _dare(As / math.exp(-(mu + frac * gap) * dt), Q0, sh)
        if X is not None:
            yield X / back


def _dare(Ah: np.ndarray, Q: np.ndarray, sh: float) -> np.ndarray | None:
    """The stabilising solution of the discrete KYP Riccati equation (``b = A e3``)."""
    from scipy.linalg import solve_discrete_are

    e3 = np.array([[0.0], [0.0], [1.0]])
    try:
        with np.errstate(all="ignore"):
            X = solve_discrete_are(Ah, Ah[:, 2:3].copy(), Q, -np.ones((1, 1)), s=-sh * e3)
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(X)):
        return None
    return (X + X.T) / 2
