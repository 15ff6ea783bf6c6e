"""Robust certificate of the sampled observer error over an uncertainty box.

Its synthesis (gains minimising the certified bound) is
:func:`bwdesign.design.synthesize_robust_observer`.

The observer is the sampled PHSO (predict/update, ``K = discrete_gains(model, l, dt)``)
built on the *model* ``params``; the true plant is any point ``theta`` of the
:class:`~bwdesign.UncertaintyBox`, driven by any input in the operating range
``u in [u_lo, u_hi]`` with ``|du| <= udot_max dt`` (no controller, no reference).

Error system
------------
With ``e = xhat - x`` the *posterior* error, one sample is exactly (no approximation)::

    e+ = (I - K C) [ Fm D(rho) e + Fm e3 dh + (Fm - Fv) [x1; x2; x3 + j] + (gm - gv) u ] + K n

``D(rho) = diag(1, 1, rho)`` with ``rho`` the slope of the model's jump map between
``xhat3`` and ``x3`` (:func:`rho_interval`, time varying), ``dh = Hm(x3) - Hv(x3)`` the
model-minus-plant jump at the plant's ``x3``, ``x3 + j = Hv(x3)`` the plant's
hysteresis after the jump and ``n`` the sensor noise (``|n| <= noise_max``). The
homogeneous part uses only model matrices; the box enters through the bounded inputs:

- ``|dh| <= (|dalpha| + (|dbeta| + |dgamma|) H) |du| exp((|beta| + |gamma|) |du|)``
  (as :mod:`.robust`), ``|du| <= udot_max dt``;
- the mismatch ``m = (Fm - Fv)[x1; x2; w] + (gm - gv) u`` (``w = x3 + j``, its third
  row is 0). The plant's ``(x1, x2)`` is the output of its stable linear part driven by
  ``u`` and ``w``, so ``m`` is a linear time-invariant response of the plant's input
  sequences ``u`` and ``w``: ``m_k = m_c + sum_i h_i (u_{k-i} - u_c, w_{k-i})``. Each
  component is bounded by the steady response ``m_c`` to the range centre ``u_c`` plus
  the l1 norm of the discrete impulse response ``h`` times the half ranges
  (``(u_hi - u_lo) / 2`` and ``h_max`` of the plant, since ``|Hv(x3)| <= h_max`` for a
  plant that starts with ``|x3| <= h_max``), or, when smaller, by the quasi-static
  response (steady gain times the ranges) plus the l1 norm of the step-response error
  ``S - S_i`` times the per-sample increments ``|du| <= udot_max dt`` and the plant's
  jump ``|dw|`` (summation by parts: this uses the rate limit). The sums run to a
  horizon with a rigorous geometric tail (a Lyapunov norm of the plant's ``Phi``). It
  is a bound for every sample when the plant starts at rest at an equilibrium of an
  admissible constant input (as if that input had been applied forever); from any
  other initial state it holds after the plant's own transient ``Phi^k x(0)`` has
  died out.

An input disturbance (``disturbance=DisturbanceBound(input_max, rate_max)``: the
plant's linear part sees ``u + d``, ``|d| <= input_max``, ``|d'| <= rate_max``; the
observer, its hysteresis copy and the plant's hysteresis see ``u``) changes the error
step by ``(I - K C)[m(u + d) - gm d - r]``: the mismatch is bounded as above for the
input ``v = u + d`` (range widened by ``input_max``, increments ``|dv| <= udot_max dt +
rate_max dt``), ``gm d`` is the model's input column times ``input_max``, and ``r`` (a
``d`` moving within the sample, :func:`~bwdesign.certify.ellipsoid.disturbance_remainder`)
enters directly and through the plant's later mismatch (the l1 norm of ``dPhi
Phi^(i-1)``). These add to the ``m1``, ``m2`` channels; with no disturbance they are 0.
There is no slow/fast split here (no reference, no integrator): ``d`` is an arbitrary
bounded input for this certificate, which keeps it simple and conservative.

Certificate
-----------
One quadratic ``V = e'Pe`` for both ends of ``rho`` (common, because ``rho_k`` changes
every sample): ``V(e+) <= a V(e) + (1 - a) sum lam_j w_j^2`` with the inputs
normalised to ``|w_j| <= 1`` (LMI :func:`bwdesign.certify.lmi.robust_ellipsoid`, the
contraction ``a`` searched as in :mod:`.robust`). The error converges at rate
``-ln(a) / (2 dt)`` into ``{e'Pe <= 1}`` and stays there, so in steady state
``|x1hat - x1| <= sqrt(c'P^-1 c)`` (likewise ``x3``). The input bounds are the maxima
over the box's corners and seeded interior points (the ZOH matrices are not affine
in the parameters: an unsampled interior point could exceed them slightly; the
details say whether an interior point exceeded every corner). The state is balanced
and scaled, every block re-checked with ``numpy.linalg.eigvalsh`` outside the
solver, the bound recomputed with numpy; solver trouble is a status, never a
certificate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import matrix_balance, solve_discrete_lyapunov

from ..errors import InputError
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_sample_time, discretize, hysteresis_slope_range
from ..model.uncertainty import DisturbanceBound, UncertaintyBox, disturbance_bounds
from ..observers.gains import as_gains, check_gains, discrete_gains
from ..validate import NONNEGATIVE, SEED, SIGNAL, UDOT_MAX, integer, real
from .checks import rho_interval
from .ellipsoid import (
    disturbance_remainder,
    jump_mismatch,
    schur_min_eig,
    search_log_contraction,
)
from .results import CONTRACTION, Margin, worst_margin

__all__ = [
    "BoxSampling",
    "RobustObserverCertificate",
    "RobustObserverProblem",
    "certify_robust_observer",
    "certify_robust_observer_discrete",
    "robust_observer_problem",
]

_C = np.array([1.0, 0.0, 0.0])


@dataclass(frozen=True)
class BoxSampling:
    """The seeded interior points of the box a robust observer certificate adds to its corners.

    Parameters
    ----------
    interior_samples : int
        Interior points (``>= 0``) whose input bounds are included.
    seed : int
        Seed of ``numpy.random.default_rng`` that draws them.
    """

    interior_samples: int = 16
    seed: int = 0

    def __post_init__(self) -> None:
        n = integer(self.interior_samples, "interior_samples", within=NONNEGATIVE)
        object.__setattr__(self, "interior_samples", n)
        object.__setattr__(self, "seed", integer(self.seed, "seed", within=SEED))

    def points(self, uncertainty: UncertaintyBox, params: BoucWenParams) -> list[BoucWenParams]:
        """The interior plants (:meth:`UncertaintyBox.sample` with this seed)."""
        rng = np.random.default_rng(self.seed)
        return uncertainty.sample(params, rng, self.interior_samples)


def _sampling(sampling: Any) -> BoxSampling:
    if sampling is None:
        return BoxSampling()
    if not isinstance(sampling, BoxSampling):
        raise InputError(f"sampling must be a BoxSampling or None, got {type(sampling).__name__}")
    return sampling


@dataclass(frozen=True)
class RobustObserverCertificate:
    """Robust convergence and steady estimation-error bounds of the sampled PHSO over a box.

    Attributes
    ----------
    holds : bool
        A common ``P`` over both ``rho`` ends passed the outside check with the input
        bounds of every corner and interior sample.
    status : str
    decay : float or None
        Certified convergence rate of the error into the ellipsoid (1/s).
    estimation_bound, x3_estimation_bound : float or None
        Certified steady bounds on ``|x1hat - x1|`` and ``|x3hat - x3|`` (posterior,
        at the sample instants, length unit).
    a : float
        Contraction factor per sample used in the LMI.
    noise_max : float
        Sensor noise bound assumed (length unit).
    input_range : tuple of 2 floats
        ``(u_lo, u_hi)`` (input unit) the plant may be driven with.
    n_vertices, n_interior : int
    input_bounds : dict
        Bound of each exogenous channel per sample: ``dh`` (length unit), the mismatch
        rows ``m1`` (length unit) and ``m2`` (length unit/s), ``noise`` (length unit).
    margins : tuple of Margin
        Smallest eigenvalue per checked block (passed when ``-min eig < 0``).
    solver : str
    details : dict
    """

    holds: bool
    status: str
    decay: float | None
    estimation_bound: float | None
    x3_estimation_bound: float | None
    a: float
    noise_max: float
    input_range: tuple[float, float]
    n_vertices: int
    n_interior: int
    input_bounds: dict[str, Any]
    margins: tuple[Margin, ...] = ()
    solver: str = ""
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        worst = worst_margin(self.margins)
        return {
            "holds": self.holds,
            "status": self.status,
            "decay": self.decay,
            "estimation_bound": self.estimation_bound,
            "x3_estimation_bound": self.x3_estimation_bound,
            "a": self.a,
            "noise_max": self.noise_max,
            "input_range": list(self.input_range),
            "n_vertices": self.n_vertices,
            "n_interior": self.n_interior,
            "input_bounds": self.input_bounds,
            "worst_margin": None if worst is None else worst.to_dict(),
            "solver": self.solver,
            "details": self.details,
        }


def _response_l1(
    Phi: np.ndarray, b: np.ndarray, dPhi: np.ndarray, d0: np.ndarray, scale: float
) -> np.ndarray:
    """``sum_k |h_k|`` of ``h_0 = d0``, ``h_k = dPhi Phi^(k-1) b`` (componentwise, rigorous).

    Summed (in blocks) until the remainder is below 1e-9 of the sum, then the tail bounded in the
    Lyapunov norm of ``Phi`` (``||Phi x||_L <= q ||x||_L``): ``|dPhi_i y| <=
    ||dPhi_i||_{L^-1} ||y||_L`` and ``sum_j q^j = 1 / (1 - q)``. ``scale`` balances
    the second state (``x2 ~ sqrt(a1) x1``).
    """
    S = np.array([1.0, scale])
    Ps = Phi * S[None, :] / S[:, None]
    bs = b / S
    Ds = dPhi * S[None, :]
    L = solve_discrete_lyapunov(Ps.T, np.eye(2))
    L = (L + L.T) / 2
    q = math.sqrt(max(0.0, 1.0 - 1.0 / float(np.linalg.eigvalsh(L).max())))
    Linv = np.linalg.inv(L)
    row_norm = np.sqrt(np.einsum("ij,jk,ik->i", Ds, Linv, Ds))
    # blocks of M samples: row k of Y is Phi^k b; the next block is Y (Phi^M)'
    M = 256
    Y = np.empty((M, 2))
    Y[0] = bs
    for k in range(1, M):
        Y[k] = Ps @ Y[k - 1]
    PM = np.linalg.matrix_power(Ps, M)
    total = np.abs(d0).astype(float)
    for _ in range(1 << 14):
        total = total + np.abs(Y @ Ds.T).sum(axis=0)
        Y = Y @ PM.T
        y = Y[0]
        tail = row_norm * math.sqrt(max(float(y @ L @ y), 0.0)) / (1.0 - q)
        if np.all(tail <= 1e-9 * np.maximum(total, 1e-300)):
            break
    return total + tail


def _mismatch_bound(
    model: BoucWenParams, tp: BoucWenParams, dt: float, u_range: tuple[float, float], du, dv
) -> np.ndarray:
    """Bound of ``|m|`` (rows 1, 2) for plant ``tp`` over the input range (module doc).

    Per component the smaller of two valid bounds: the amplitude one ``|m_c| + l1(h^u)
    u_r + l1(h^w) h_max`` and the rate one (summation by parts, ``S = sum h``):
    ``|S^u u_c| + |S^u| u_r + |S^w| h_max + l1(S - S_i)^u |dv| + l1(S - S_i)^w |dw|``
    with ``|dw| <= hi |du|`` the plant's jump (``hi`` from
    :func:`~bwdesign.model.plant.hysteresis_slope_range`). ``u_range``
    and ``dv`` are of the input the plant's linear part sees (``u + d``), ``du`` of ``u``.
    """
    u_lo, u_hi = u_range
    zm, zv = discretize(model, dt), discretize(tp, dt)
    Phim, Phiv = np.asarray(zm.F)[:2, :2], np.asarray(zv.F)[:2, :2]
    bwm, bwv = np.asarray(zm.F)[:2, 2], np.asarray(zv.F)[:2, 2]
    bum, buv = np.asarray(zm.g)[:2], np.asarray(zv.g)[:2]
    dPhi = Phim - Phiv
    uc, ur = (u_hi + u_lo) / 2, (u_hi - u_lo) / 2
    hv = tp.bounded_class().h_max
    dw = hysteresis_slope_range(tp)[1] * du
    w0 = math.sqrt(tp.a1)
    R = np.linalg.inv(np.eye(2) - Phiv)
    Su = dPhi @ R @ buv + (bum - buv)  # steady gains, so m_c = Su u_c
    Sw = dPhi @ R @ bwv + (bwm - bwv)
    amplitude = (
        np.abs(Su * uc)
        + ur * _response_l1(Phiv, buv, dPhi, bum - buv, w0)
        + hv * _response_l1(Phiv, bwv, dPhi, bwm - bwv, w0)
    )
    zero = np.zeros(2)
    rate = (
        np.abs(Su * uc)
        + np.abs(Su) * ur
        + np.abs(Sw) * hv
        + dv * _response_l1(Phiv, R @ buv, dPhi, zero, w0)
        + dw * _response_l1(Phiv, R @ bwv, dPhi, zero, w0)
    )
    return np.minimum(amplitude, rate)


@dataclass(frozen=True)
class RobustObserverProblem:
    """Everything but the gain: channels (unscaled), rho ends, scaling, box bookkeeping."""

    F: np.ndarray
    Bw: np.ndarray  # 3 x 3 columns before (I - K C): Fm e3 DH, e1 M1, e2 M2
    noise: float
    rho: tuple[float, float]
    input_bounds: dict[str, Any]
    base: dict[str, Any]
    details: dict[str, Any]
    refused: str = ""


def _problem(
    params: BoucWenParams,
    *,
    dt: float,
    uncertainty: Any,
    udot_max: float,
    input_range: Any,
    noise_max: float,
    sampling: Any,
    disturbance: Any,
) -> RobustObserverProblem:
    require_bounded(params)
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_MAX)
    noise_max = real(noise_max, "noise_max", within=NONNEGATIVE)
    if not isinstance(uncertainty, UncertaintyBox):
        raise InputError("uncertainty must be an UncertaintyBox")
    uncertainty.check(params, bounded=False)  # a box leaving the class: "no", not an error
    try:
        u_lo, u_hi = input_range
    except (TypeError, ValueError):
        raise InputError(f"input_range must be (u_lo, u_hi), got {input_range!r}") from None
    u_lo = real(u_lo, "input_range u_lo (V)", within=SIGNAL)
    u_hi = real(u_hi, "input_range u_hi (V)", within=SIGNAL)
    if not u_lo < u_hi:
        raise InputError(f"input_range must be finite with u_lo < u_hi, got {input_range!r}")
    sampling = _sampling(sampling)
    dist = disturbance_bounds(disturbance)
    vertices = uncertainty.vertices(params)
    interior = sampling.points(uncertainty, params)
    rho = rho_interval(params, udot_max, dt)
    base = {
        "n_vertices": len(vertices),
        "n_interior": len(interior),
        "noise_max": noise_max,
        "input_range": (u_lo, u_hi),
    }
    F = np.asarray(discretize(params, dt).F, float)
    outside = [tp for tp in vertices if not tp.bounded_class().bounded]
    if outside:
        # no h_max for such a plant: its x3 (and so the mismatch) has no bound
        reason = (
            f"the box is too wide: {len(outside)} of its {len(vertices)} corners leave the "
            f"bounded class ({outside[0].name}: {outside[0].bounded_class().reason})"
        )
        return RobustObserverProblem(
            F, np.zeros((3, 3)), noise_max, rho, {}, base, {"dt": dt}, reason
        )
    du = udot_max * dt
    per = []
    for tp in [*vertices, *interior]:
        dh = jump_mismatch(params, tp, du)
        m = _mismatch_bound(params, tp, dt, (u_lo - dist[0], u_hi + dist[0]), du, du + dist[1] * dt)
        if dist != (0.0, 0.0):
            m = m + _disturbance_terms(params, tp, dt, dist)
        per.append(np.concatenate([[dh], m]))
    per = np.array(per)
    nv = len(vertices)
    W = per.max(axis=0)
    exceeds = bool(interior) and bool(np.any(per[nv:].max(axis=0) > per[:nv].max(axis=0)))
    Bw = np.column_stack([F[:, 2] * W[0], np.eye(3)[:, 0] * W[1], np.eye(3)[:, 1] * W[2]])
    return RobustObserverProblem(
        F=F,
        Bw=Bw,
        noise=noise_max,
        rho=rho,
        input_bounds={"dh": float(W[0]), "m1": float(W[1]), "m2": float(W[2]), "noise": noise_max}
        | ({"disturbance": {"input_max": dist[0], "rate_max": dist[1]}} if any(dist) else {}),
        base=base,
        details={
            "rho_interval": list(rho),
            "interior_exceeds_corners": exceeds,
            "udot_max": udot_max,
            "dt": dt,
        },
    )


def _disturbance_terms(
    model: BoucWenParams, tp: BoucWenParams, dt: float, dist: tuple[float, float]
) -> np.ndarray:
    """What the input disturbance adds to ``|m|`` beyond the widened input (module doc).

    ``gm d`` (the model's input column: the plant's ``gv d`` and the mismatch's ``(gm -
    gv) d`` together), the within-sample remainder ``r`` directly and through the
    plant's later mismatch ``sum_i dPhi Phi^(i-1) r``.
    """
    zm, zv = discretize(model, dt), discretize(tp, dt)
    Phiv, dPhi = np.asarray(zv.F)[:2, :2], (np.asarray(zm.F) - np.asarray(zv.F))[:2, :2]
    r = disturbance_remainder(tp.a3, dist[1], dt)
    out = np.abs(np.asarray(zm.g)[:2]) * dist[0] + r
    if dist[1] > 0:
        w0 = math.sqrt(tp.a1)
        for j in range(2):
            out = out + r[j] * _response_l1(Phiv, np.eye(2)[j], dPhi, np.zeros(2), w0)
    return out


def robust_observer_problem(
    params: BoucWenParams,
    *,
    dt: float,
    uncertainty: UncertaintyBox,
    udot_max: float,
    input_range: tuple[float, float],
    noise_max: float = 0.0,
    sampling: BoxSampling | None = None,
    disturbance: DisturbanceBound | None = None,
) -> RobustObserverProblem:
    """The gain-free part of :func:`certify_robust_observer`'s problem, checked.

    The error channels, the jump-slope ends ``rho`` and the input bounds over the box
    (``refused`` says why there is no certificate for any gain); the synthesis
    (:func:`bwdesign.design.synthesize_robust_observer`) solves for the gain on it.
    Parameters as :func:`certify_robust_observer`.
    """
    return _problem(
        params,
        dt=check_sample_time(params, dt),
        uncertainty=uncertainty,
        udot_max=udot_max,
        input_range=input_range,
        noise_max=noise_max,
        sampling=sampling,
        disturbance=disturbance,
    )


def _blocks(pb: RobustObserverProblem, K: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    G = np.eye(3) - np.outer(K, _C)
    A = [G @ pb.F @ np.diag([1.0, 1.0, r]) for r in pb.rho]
    B = np.column_stack([G @ pb.Bw, K * pb.noise])
    return A, B


def _scaling(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Balance, then the square root of the steady covariance's diagonal (``P`` O(1))."""
    _, (s, _) = matrix_balance(A, permute=False, separate=True)
    s = np.asarray(s, float)
    if float(np.max(np.abs(np.linalg.eigvals(A)))) >= 1:
        return s
    Ab = A * s[None, :] / s[:, None]
    Bb = B / s[:, None]
    X = solve_discrete_lyapunov(Ab, Bb @ Bb.T)
    return s * np.sqrt(np.maximum(np.diag(X), 1e-12 * float(np.max(np.diag(X)))))


def _check(Q: np.ndarray, lam: np.ndarray, a: float, blocks) -> list[Margin]:
    """Every LMI block with eigvalsh outside the solver (equilibrated by its diagonal)."""
    Q = (Q + Q.T) / 2
    margins = [Margin("Q > 0", -float(np.linalg.eigvalsh(Q).min()), 0.0)]
    for idx, (A, B) in enumerate(blocks):
        ev = schur_min_eig(Q, lam, A, B, a)
        margins.append(Margin(f"Schur block rho end {idx} > 0", -ev, 0.0))
    return margins


def _not(
    pb: RobustObserverProblem, status: str, a: float, solver: str = "", **extra
) -> RobustObserverCertificate:
    return RobustObserverCertificate(
        holds=False,
        status=f"not certified: {status}",
        decay=None,
        estimation_bound=None,
        x3_estimation_bound=None,
        a=a,
        input_bounds=pb.input_bounds,
        solver=solver,
        details=pb.details | extra,
        **pb.base,
    )


def _certify_K(
    pb: RobustObserverProblem, K: np.ndarray, a: float | None
) -> RobustObserverCertificate:
    from . import lmi

    rho_lo, rho_hi = pb.rho
    if pb.refused:
        return _not(pb, pb.refused, math.nan)
    if not math.isfinite(rho_hi):
        return _not(pb, "the model's jump-map slope interval is unbounded", math.nan)
    if not all(math.isfinite(pb.input_bounds[k]) for k in ("dh", "m1", "m2", "noise")):
        return _not(
            pb,
            "an input bound is infinite (the hysteresis mismatch at this input rate: "
            f"dh <= {pb.input_bounds['dh']:g})",
            math.nan,
        )
    A_list, B = _blocks(pb, K)
    keep = np.any(B != 0, axis=0)
    B = B[:, keep]
    spec = max(float(np.max(np.abs(np.linalg.eigvals(A)))) for A in A_list)
    if spec >= 1:
        why = "expanding" if rho_hi > 1 else "not contracting"
        return _not(
            pb,
            f"the error dynamics are not Schur stable at an end of rho in [{rho_lo:.6g}, "
            f"{rho_hi:.6g}] (spectral radius {spec:.6g} >= 1; the rho interval is {why})",
            math.nan,
            spectral_radius=spec,
        )
    s = _scaling(_blocks(pb, K)[0][0] @ np.diag([1.0, 1.0, 1.0 / rho_lo]), B)
    blocks = [(A * s[None, :] / s[:, None], B / s[:, None]) for A in A_list]
    As, Bs = [b[0] for b in blocks], [b[1] for b in blocks]
    targets = {"x1": _C, "x3": np.eye(3)[2]}

    def attempt(av: float, c: np.ndarray):
        return lmi.robust_ellipsoid(As, Bs, s * c, a=av)

    if a is None:
        cache: dict[float, Any] = {}

        def f(x: float) -> float:
            if x not in cache:
                av = 1 - math.exp(x)
                sol = attempt(av, targets["x1"])
                cache[x] = (sol, av, sol.objective if sol.ok else math.inf)
            return cache[x][2]

        lo, hi = math.log(1e-6), math.log(1 - spec**2)
        search_log_contraction(f, list(np.linspace(hi, lo, 12)), 5)
        ok = [v for v in cache.values() if v[0].ok]
        sol, av = min(ok, key=lambda v: v[2])[:2] if ok else (None, math.nan)
    else:
        av = real(a, "a", within=CONTRACTION)
        sol = attempt(av, targets["x1"])
    if sol is None or not sol.ok:
        why = sol.status if sol is not None else "infeasible for every contraction tried"
        return _not(
            pb,
            f"no common Lyapunov function for rho in [{rho_lo:.6g}, {rho_hi:.6g}] ({why})",
            av,
            solver=sol.solver if sol is not None else "",
            spectral_radius=spec,
        )
    bounds: dict[str, float | None] = {}
    margins: list[Margin] = []
    for name, c in targets.items():
        s2 = sol if name == "x1" else attempt(av, c)
        if not s2.ok:
            bounds[name] = None
            continue
        lam = np.maximum(np.asarray(s2["lam"]), 0.0)
        Q = np.asarray(s2["Q"])
        m2 = _check(Q, lam, av, blocks)
        if name == "x1":
            margins = m2
        cs = s * c
        ok = all(m.passed for m in m2)
        bounds[name] = (
            math.sqrt(float(lam.sum()) * float(cs @ ((Q + Q.T) / 2) @ cs)) if ok else None
        )
    holds = all(m.passed for m in margins) and bounds["x1"] is not None
    if holds and bounds["x3"] is None:
        # the x1 ellipsoid is invariant too: its x3 extent is a (looser) bound
        Q, lam = np.asarray(sol["Q"]), np.maximum(np.asarray(sol["lam"]), 0.0)
        cs = s * targets["x3"]
        bounds["x3"] = math.sqrt(float(lam.sum()) * float(cs @ ((Q + Q.T) / 2) @ cs))
    decay = -math.log(av) / (2 * pb.details["dt"])
    if not holds:
        worst = max(margins, key=lambda m: m.value - m.limit)
        return _not(
            pb,
            f"the solver's P failed the outside check ({worst.name}: min eig {-worst.value:.3g})",
            av,
            solver=sol.solver,
            spectral_radius=spec,
        )
    nb = pb.base
    return RobustObserverCertificate(
        holds=True,
        status=(
            f"certified over {nb['n_vertices']} corners (+{nb['n_interior']} interior points) "
            f"for u in [{nb['input_range'][0]:g}, {nb['input_range'][1]:g}]: steady "
            f"|x1hat - x1| <= {bounds['x1']:.4g}, |x3hat - x3| <= {bounds['x3']:.4g} "
            f"(length unit), convergence >= {decay:.4g} 1/s" + _disturbance_note(pb)
        ),
        decay=decay,
        estimation_bound=bounds["x1"],
        x3_estimation_bound=bounds["x3"],
        a=av,
        input_bounds=pb.input_bounds,
        margins=tuple(margins),
        solver=sol.solver,
        details=pb.details | {"spectral_radius": spec, "K": K.tolist()},
        **nb,
    )


def _disturbance_note(pb: RobustObserverProblem) -> str:
    dist = pb.input_bounds.get("disturbance")
    if dist is None:
        return ""
    return (
        f", with an input disturbance |d| <= {dist['input_max']:.4g}, |d'| <= "
        f"{dist['rate_max']:.4g} /s (input unit) on the plant"
    )


def certify_robust_observer(
    params: BoucWenParams,
    gains: Any,
    *,
    dt: float,
    uncertainty: UncertaintyBox,
    udot_max: float,
    input_range: tuple[float, float],
    noise_max: float = 0.0,
    sampling: BoxSampling | None = None,
    a: float | None = None,
    disturbance: DisturbanceBound | None = None,
) -> RobustObserverCertificate:
    """Certify the sampled PHSO's estimation error over every plant in an uncertainty box.

    Parameters
    ----------
    params : BoucWenParams
        The model the observer runs.
    gains : sequence of 3 floats
        Continuous observer gains (pole-matched to ``K`` as the observer runs them);
        :func:`certify_robust_observer_discrete` takes ``K`` itself.
    dt : float
        Sample time (s).
    uncertainty : UncertaintyBox
        The box of true plants (finite half-widths).
    udot_max : float
        Input-rate envelope (V/s): ``|du| <= udot_max dt``.
    input_range : (float, float)
        ``(u_lo, u_hi)``: the inputs (V) the plant may be driven with.
    noise_max : float
        Sensor noise bound ``|n| <= noise_max`` (length unit).
    sampling : BoxSampling, optional
        The seeded interior points of the box whose input bounds are included
        (default ``BoxSampling()``: 16 points, seed 0).
    a : float, optional
        Contraction per sample in ``(0, 1)``; default: searched for the smallest x1 bound.
    disturbance : DisturbanceBound, optional
        A slowly varying input-equivalent disturbance on the plant (``x2' = ... + a3 (u
        + d)``, ``|d| <= input_max``, ``|d'| <= rate_max``; the observer does not see it):
        the plant's linear part sees ``u + d``; see the module doc. ``None``: none.

    Returns
    -------
    RobustObserverCertificate
    """
    dt = check_sample_time(params, dt)
    K = discrete_gains(params, check_gains(params, gains), dt)
    return certify_robust_observer_discrete(
        params, K, dt=dt, uncertainty=uncertainty, udot_max=udot_max, input_range=input_range,
        noise_max=noise_max, sampling=sampling, a=a, disturbance=disturbance,
    )  # fmt: skip


def certify_robust_observer_discrete(
    params: BoucWenParams,
    K: Any,
    *,
    dt: float,
    uncertainty: UncertaintyBox,
    udot_max: float,
    input_range: tuple[float, float],
    noise_max: float = 0.0,
    sampling: BoxSampling | None = None,
    a: float | None = None,
    disturbance: DisturbanceBound | None = None,
) -> RobustObserverCertificate:
    """:func:`certify_robust_observer` of the discrete gain ``K`` itself (as ``certify_discrete``).

    For a design whose discrete poles have no continuous equivalent (a synthesis in the
    z-plane). ``K`` is the predict/update gain; the other parameters as there.
    """
    K = np.asarray(as_gains(K, "discrete gains K"), float)
    pb = robust_observer_problem(
        params, dt=dt, uncertainty=uncertainty, udot_max=udot_max, input_range=input_range,
        noise_max=noise_max, sampling=sampling, disturbance=disturbance,
    )  # fmt: skip
    return _certify_K(pb, K, a)
