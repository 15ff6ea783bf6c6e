"""Certified observer gains: four certificate tiers and LMI gain synthesis.

The observer error ``eps = x_hat - x`` of the hysteresis observer (paper eq. 3)
obeys (DESIGN.md section 3)::

    eps' = A eps + e3 phi~,   A = A0 - l C,   C = e1',
    A0 = [[0, 1, 0], [-a1, -a2, -a1], [0, 0, 0]],
    phi~ = -k(t) eps3,  k in [min(0, (beta - |gamma|) v), max(0, (beta + |gamma|) v)]

for ``|u'| <= v`` (``v = udot_max``, V/s). The tiers, weakest first:

``theorem1``
    The paper's argument with the sign corrected: ``A'P + PA <= -q I`` and
    ``|phi~| <= L ||eps||`` with ``L = (|beta| + |gamma|) v`` give
    ``V' <= -(q - 2 L ||P||) ||eps||^2``, so it holds iff ``2 L ||P|| < q``.
    Checked for the Lyapunov-equation ``P`` (``q = 1``) and for the least-norm
    ``P`` of the LMI ``A'P + PA <= -I``. Envelope and decay are closed form.
    (The two norms coincide: the Lyapunov operator is monotone, so the
    Lyapunov-equation ``P`` is the least element of that LMI's feasible set;
    the LMI is solved in ``Q = -(A'P + PA) >= I``, where it is well conditioned,
    as a cross-check.)
``lipschitz``
    S-procedure LMI using only ``|phi~| <= L |eps3|``:
    ``[[A'P + PA + 2 mu P + L^2 e3 e3', P e3], [e3' P, -1]] < 0``. By the KYP
    lemma this is ``||e3' (sI - A - mu I)^-1 e3||_inf < 1/L``.
``sector``
    A common quadratic Lyapunov function for ``A - k e3 e3'`` at both ends of
    the ``k`` interval (polytopic LMI); it keeps the sign information
    (``beta >= |gamma|`` makes the hysteresis error dissipative).
``sampled`` (when ``dt`` is given)
    The observer that runs at sample time ``dt`` in predict/update form has
    posterior error ``eps_{k+1} = (I - K C) F diag(1, 1, rho_k) eps_k`` with
    ``F = expm(A0 dt)`` and ``rho_k`` the slope of the exact hysteresis jump
    map, ``rho in [min(1, exp(-(beta + |gamma|) v dt)),
    max(1, exp(-(beta - |gamma|) v dt))]``. The tier is the polytopic discrete
    LMI ``A_d' P A_d <= r^2 P`` over the two ends; decay ``mu = -ln(r)/dt``.
    Continuous gains are mapped to ``K`` by pole matching with the observers'
    own :func:`bwdesign.observers.discrete_gains`, so the tier certifies exactly
    the gain the sampled :class:`~bwdesign.HysteresisObserver` runs.

Numerics: every LMI is solved in scaled coordinates (``x2`` scaled by
``w0 = sqrt(a1)``, time by ``w0``, then diagonal balancing), because ``a1``
spans 1e3..1e9. The solver's matrices are mapped back, and a tier says
``holds: true`` only after ``P > 0`` and every LMI block has been re-checked in
the original coordinates with ``numpy.linalg.eigvalsh`` (see :class:`Margin`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import logm, matrix_balance, solve_continuous_lyapunov

from .errors import GainError, InputError
from .observers import _as_gains, check_gains, discrete_gains, error_matrix
from .params import BoucWenParams, require_bounded
from .plant import _check_dt, discretize

__all__ = [
    "TIERS",
    "Margin",
    "TierCertificate",
    "CertificateReport",
    "SynthesisResult",
    "certify",
    "certify_discrete",
    "synthesize",
    "continuous_equivalent",
    "sector_interval",
    "rho_interval",
    "default_pole_radius",
]

#: Tier names, weakest first; ``best`` is the last one that holds.
TIERS: tuple[str, ...] = ("theorem1", "lipschitz", "sector", "sampled")

#: Relative margin of the outside check: the largest eigenvalue of each
#: equilibrated LMI block must be below ``-REL_MARGIN * ||block||``.
REL_MARGIN = 1e-9
#: Relative resolution of the bisections for ``max_udot`` and ``decay_rate``.
BISECT_RTOL = 0.01
#: Search limit for ``max_udot``: ``(|beta| + |gamma|) v <= K_HAT_CAP * sqrt(a1)``.
K_HAT_CAP = 1e3

_U = float(np.finfo(float).eps) / 2  # unit round-off
_E3 = np.array([0.0, 0.0, 1.0])
_C = np.array([1.0, 0.0, 0.0])


# -- data objects -------------------------------------------------------------


@dataclass(frozen=True)
class Margin:
    """One inequality checked outside the solver: it passes when ``value < limit``.

    For a matrix block that must be negative definite, ``value`` is the largest
    eigenvalue of the block after equilibration by its own diagonal (a
    congruence, which preserves definiteness) plus a bound on the round-off in
    forming the block, and ``limit`` is ``-REL_MARGIN`` times the block's norm.
    For Theorem 1, ``value = 2 L ||P||`` and ``limit = q``.

    Attributes
    ----------
    name : str
        What was checked, e.g. ``"P > 0"`` or ``"He(P A_k) < 0 at k = 149 1/s"``.
    value, limit : float
    """

    name: str
    value: float
    limit: float

    @property
    def passed(self) -> bool:
        """True when ``value < limit`` (both finite)."""
        return bool(math.isfinite(self.value) and self.value < self.limit)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": self.value,
            "limit": self.limit,
            "passed": self.passed,
        }


@dataclass(frozen=True)
class TierCertificate:
    """The verdict of one certificate tier.

    Attributes
    ----------
    name : str
        ``"theorem1"``, ``"lipschitz"``, ``"sector"`` or ``"sampled"``.
    holds : bool
        The tier certifies exponential convergence at ``udot_max`` with at least
        the requested ``decay``, and its ``P`` passed the outside check.
    udot_max : float
        The input-rate bound asked about (V/s).
    decay : float
        The requested decay rate (1/s).
    max_udot : float
        The largest ``|u'|`` bound (V/s) this tier certifies for these gains with
        the requested decay (bisection to 1 %; closed form for ``theorem1``).
        0 when nothing is certified; ``inf`` when the tier provably holds for
        every rate (``sampled`` with ``beta >= |gamma|``, where the jump-map
        slope stays in ``[0, 1]`` and the LMI holds on that whole interval).
    max_udot_capped : bool
        True when the tier still held at the search limit: the true envelope is
        at least ``max_udot`` (the LMI may hold for every rate).
    decay_rate : float
        The largest certified exponential rate ``mu`` (1/s) at ``udot_max``:
        ``||eps(t)|| <= c exp(-mu t) ||eps(0)||``. 0 where none.
    P : ndarray or None
        The Lyapunov matrix in original coordinates when the tier holds.
    margins : tuple of Margin
        The inequalities checked outside the solver for the verdict at
        ``udot_max``.
    solver : str
        Solver that produced ``P`` (``"scipy"`` for the Lyapunov equation).
    status : str
        ``"certified"`` or a sentence saying why not.
    details : Mapping
        Tier-specific numbers (see :meth:`to_dict`).
    """

    name: str
    holds: bool
    udot_max: float
    decay: float
    max_udot: float
    max_udot_capped: bool
    decay_rate: float
    P: np.ndarray | None
    margins: tuple[Margin, ...]
    solver: str
    status: str
    details: Mapping[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: ``name``, ``holds``, ``max_udot``, ``decay_rate``, then details."""
        out: dict[str, Any] = {
            "name": self.name,
            "holds": self.holds,
            "max_udot": self.max_udot,
            "decay_rate": self.decay_rate,
            "max_udot_capped": self.max_udot_capped,
            "max_udot_unbounded": math.isinf(self.max_udot),
            "udot_max": self.udot_max,
            "decay": self.decay,
            "P": None if self.P is None else self.P.tolist(),
            "margins": [m.to_dict() for m in self.margins],
            "solver": self.solver,
            "status": self.status,
        }
        out.update(_plain(dict(self.details)))
        return out


@dataclass(frozen=True)
class CertificateReport:
    """All tiers for one set of gains at one operating envelope.

    Attributes
    ----------
    params : BoucWenParams
    gains : tuple of 3 floats or None
        Continuous-time gains ``(l1, l2, l3)`` (1/s, 1/s^2, 1/s); ``None`` for a
        report made from discrete gains only (:func:`certify_discrete`).
    udot_max : float
        Input-rate bound (V/s).
    decay : float
        Requested decay rate (1/s).
    dt : float or None
        Sample time (s) of the ``sampled`` tier.
    discrete_gains : tuple of 3 floats or None
        The discrete update gain ``K`` the ``sampled`` tier certified.
    certificates : tuple of TierCertificate
        One per tier, weakest first.
    """

    params: BoucWenParams
    gains: tuple[float, float, float] | None
    udot_max: float
    decay: float
    dt: float | None
    discrete_gains: tuple[float, float, float] | None
    certificates: tuple[TierCertificate, ...]

    @property
    def certified(self) -> bool:
        """True when any tier holds."""
        return any(c.holds for c in self.certificates)

    @property
    def best(self) -> str | None:
        """The strongest tier that holds (order of :data:`TIERS`), or ``None``."""
        held = [c.name for c in self.certificates if c.holds]
        return max(held, key=TIERS.index) if held else None

    def tier(self, name: str) -> TierCertificate:
        """The certificate of tier ``name``.

        Raises
        ------
        KeyError
            The tier was not computed (``sampled`` needs ``dt``).
        """
        for c in self.certificates:
            if c.name == name:
                return c
        raise KeyError(
            f"tier {name!r} not in this report; tiers are {[c.name for c in self.certificates]}"
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict with keys ``plant``, ``gains``, ``udot_max``,
        ``certificates``, ``certified``, ``best`` (plus ``decay``, ``dt``,
        ``discrete_gains``)."""
        return {
            "plant": self.params.to_dict(),
            "gains": None if self.gains is None else list(self.gains),
            "udot_max": self.udot_max,
            "decay": self.decay,
            "dt": self.dt,
            "discrete_gains": None if self.discrete_gains is None else list(self.discrete_gains),
            "certificates": [c.to_dict() for c in self.certificates],
            "certified": self.certified,
            "best": self.best,
        }


@dataclass(frozen=True)
class SynthesisResult:
    """Gains found by :func:`synthesize`, or a clear "no".

    Attributes
    ----------
    feasible : bool
        True when gains were found *and* re-certified by :func:`certify`.
    tier : str
        The tier synthesised for: ``"sector"`` (continuous) or ``"sampled"``.
    gains : tuple of 3 floats or None
        Continuous gains ``(l1, l2, l3)``. For a sampled synthesis these are the
        exact pole-matching equivalent of the discrete gains (``None`` if the
        discrete poles have none).
    discrete_gains : tuple of 3 floats or None
        Discrete update gain ``K`` (sampled synthesis only).
    udot_max, decay, pole_radius : float
        The request: V/s, 1/s, rad/s.
    dt : float or None
        Sample time (s).
    binding : str or None
        ``None`` when feasible; otherwise the binding requirement:
        ``"decay"``, ``"pole_radius"``, ``"udot_max"``, ``"verification"`` or
        ``"solver"``.
    reason : str
        One sentence: what was certified, or which requirement cannot be met.
    max_decay : float or None
        On a decay failure, the largest decay (1/s) certifiable within the pole
        region at ``udot_max``.
    max_udot : float or None
        On an envelope failure, the largest ``|u'|`` (V/s) certifiable within
        the pole region (0 when none).
    margin : float or None
        The synthesis LMI margin ``t`` (scaled units).
    solver, status : str
        Solver of the synthesis LMI and its status.
    report : CertificateReport or None
        The re-certification of the gains.
    params : BoucWenParams
    """

    feasible: bool
    tier: str
    gains: tuple[float, float, float] | None
    discrete_gains: tuple[float, float, float] | None
    udot_max: float
    decay: float
    pole_radius: float
    dt: float | None
    binding: str | None
    reason: str
    max_decay: float | None
    max_udot: float | None
    margin: float | None
    solver: str
    status: str
    report: CertificateReport | None
    params: BoucWenParams

    @property
    def certified(self) -> bool:
        """True when the re-certification holds (same as ``feasible``)."""
        return self.feasible

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict with the certification keys (``plant``, ``gains``,
        ``udot_max``, ``certificates``, ``certified``, ``best``) and the
        synthesis fields."""
        rep = self.report
        return {
            "plant": self.params.to_dict(),
            "gains": None if self.gains is None else list(self.gains),
            "discrete_gains": None if self.discrete_gains is None else list(self.discrete_gains),
            "udot_max": self.udot_max,
            "decay": self.decay,
            "pole_radius": self.pole_radius,
            "dt": self.dt,
            "tier": self.tier,
            "feasible": self.feasible,
            "binding": self.binding,
            "reason": self.reason,
            "max_decay": self.max_decay,
            "max_udot": self.max_udot,
            "margin": self.margin,
            "solver": self.solver,
            "status": self.status,
            "certificates": [] if rep is None else [c.to_dict() for c in rep.certificates],
            "certified": self.feasible,
            "best": None if rep is None else rep.best,
        }


def _plain(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.floating | np.integer):
        return obj.item()
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


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


# -- bisections ---------------------------------------------------------------------


def _largest_rate(
    pred: Callable[[float], bool], start: float, cap: float, rtol: float = BISECT_RTOL
) -> tuple[float, bool]:
    """Largest ``v`` in ``(0, cap]`` with ``pred(v)`` (monotone), to ``rtol``.

    Returns ``(v, capped)``; ``(0, False)`` when nothing down to ``1e-12 cap`` holds.
    """
    if not math.isfinite(cap):
        cap = start * 1e12
    x = min(start, cap)
    if pred(x):
        lo = x
        while True:
            if lo >= cap:
                return cap, True
            nxt = min(lo * 4.0, cap)
            if pred(nxt):
                lo = nxt
            else:
                hi = nxt
                break
    else:
        hi = x
        floor = cap * 1e-12
        while True:
            nxt = hi / 4.0
            if nxt < floor:
                return 0.0, False
            if pred(nxt):
                lo = nxt
                break
            hi = nxt
    while hi / lo > 1.0 + rtol:
        mid = math.sqrt(lo * hi)
        if pred(mid):
            lo = mid
        else:
            hi = mid
    return lo, False


def _largest_decay(pred: Callable[[float], bool], cap: float, rtol: float = BISECT_RTOL) -> float:
    """Largest ``mu`` in ``[0, cap)`` with ``pred(mu)``, to ``rtol`` (0 if none)."""
    if not (cap > 0 and math.isfinite(cap)) or not pred(0.0):
        return 0.0
    hi = cap
    x = cap / 2.0
    floor = cap * 1e-9
    while not pred(x):
        hi = x
        x /= 4.0
        if x < floor:
            return 0.0
    lo = x
    while hi / lo > 1.0 + rtol:
        mid = math.sqrt(lo * hi)
        if pred(mid):
            lo = mid
        else:
            hi = mid
    return lo


def _search_cap(params: BoucWenParams) -> float:
    c = _lipschitz_coefficient(params)
    return K_HAT_CAP * math.sqrt(params.a1) / c if c > 0 else math.inf


def _lmi_tier(
    name: str,
    check: Callable[[float, float], _Check],
    *,
    udot_max: float,
    decay: float,
    cap: float,
    decay_cap: Callable[[float], float],
    details: dict[str, Any],
    every_rate: Callable[[float], _Check] | None = None,
) -> TierCertificate:
    check = functools.lru_cache(maxsize=None)(check)
    main = check(udot_max, decay)
    if main.ok and every_rate is not None and every_rate(decay).ok:
        max_udot, capped = math.inf, False
    else:
        max_udot, capped = _largest_rate(lambda v: check(v, decay).ok, udot_max, cap)
    rate = _largest_decay(lambda m: check(udot_max, m).ok, decay_cap(udot_max))
    if main.ok and rate < decay:
        rate = decay  # the requested decay itself was verified
    if main.t is not None:
        details = {**details, "lmi_margin": main.t}
    return TierCertificate(
        name=name,
        holds=main.ok,
        udot_max=udot_max,
        decay=decay,
        max_udot=max_udot,
        max_udot_capped=capped,
        decay_rate=rate,
        P=main.P,
        margins=main.margins,
        solver=main.solver,
        status=main.status,
        details=dict(details),
    )


# -- the tiers ----------------------------------------------------------------------


def _theorem1(params: BoucWenParams, sc: _Scaled, udot_max: float, decay: float) -> TierCertificate:
    from . import lmi

    c = _lipschitz_coefficient(params)
    L = c * udot_max
    A = sc.A

    # Lyapunov equation A'P + PA = -Q in scaled form: Ahat'X + X Ahat = -S'QS,
    # P = S^-T X S^-1 / w.
    def lyap(Qm: np.ndarray) -> np.ndarray:
        rhs = sc.s[:, None] * Qm * sc.s[None, :]
        scale = float(np.abs(rhs).max())
        X = solve_continuous_lyapunov(sc.Ahat.T, -rhs / scale)
        return scale * ((X + X.T) / 2) / np.outer(sc.s, sc.s) / sc.w

    P_lyap = lyap(np.eye(3))
    candidates: list[tuple[str, np.ndarray, str]] = [("lyapunov", P_lyap, "scipy")]
    # least-norm P over A'P + PA <= -I, as an LMI in Q = -(A'P + PA) >= I
    nL = float(np.linalg.eigvalsh(P_lyap).max())
    basis = {}
    for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
        E = np.zeros((3, 3))
        E[i, j] = E[j, i] = 1.0
        basis[(i, j)] = lyap(E)
    sol = lmi.least_norm_lyapunov({k: v / nL for k, v in basis.items()})
    lmi_status = sol.status
    if sol.ok:
        Qs = np.asarray(sol["Q"])
        P_lmi = sum(Qs[i, j] * B for (i, j), B in basis.items())
        candidates.append(("lmi", (P_lmi + P_lmi.T) / 2, sol.solver))

    results = []
    for label, P, solver in candidates:
        pos = _posdef("P > 0", P)
        M = A.T @ P + P @ A
        err = float(np.linalg.norm(_cont_err(A, P, 0.0), "fro"))
        q = -(float(np.linalg.eigvalsh((M + M.T) / 2).max()) + err)
        nP = float(np.linalg.eigvalsh(P).max()) * (1 + 8 * _U)
        ok_P = pos.passed and q > 0 and nP > 0
        results.append((label, P, solver, pos, q, nP, ok_P))

    details: dict[str, Any] = {"L": L, "lmi_status": lmi_status}
    for label, _, _, _, q, nP, _ in results:
        details[f"norm_P_{label}"] = nP
        details[f"q_{label}"] = q
        details[f"two_L_norm_P_{label}"] = 2 * L * nP
    details["two_L_norm_P"] = details["two_L_norm_P_lyapunov"]

    usable = [r for r in results if r[6]]
    if not usable:
        return TierCertificate(
            name="theorem1",
            holds=False,
            udot_max=udot_max,
            decay=decay,
            max_udot=0.0,
            max_udot_capped=False,
            decay_rate=0.0,
            P=None,
            margins=tuple(r[3] for r in results),
            solver="scipy",
            status="not certified: no Lyapunov matrix passed the outside check",
            details=dict(details),
        )
    # best candidate: the one with the largest envelope q / (2 c ||P||)
    best = max(usable, key=lambda r: r[4] / r[5])
    label, P, solver, pos, q, nP, _ = best
    rate = max(0.0, (q - 2 * L * nP) / (2 * nP))
    max_udot = max(0.0, (q - 2 * decay * nP) / (2 * c * nP)) if c > 0 else math.inf
    shortfall = 2 * L * nP / q
    details["P_used"] = label
    details["shortfall"] = shortfall
    margins = (pos, Margin("2 L ||P|| < q", 2 * L * nP, q))
    holds = margins[1].passed and rate >= decay
    if holds:
        status = "certified"
    elif not margins[1].passed:
        status = (
            f"not certified: 2 L ||P|| / q = {shortfall:.4g} >= 1 "
            f"(Theorem 1 falls short by this factor)"
        )
    else:
        status = f"not certified: decay {rate:.4g} 1/s < requested {decay:g} 1/s"
    return TierCertificate(
        name="theorem1",
        holds=holds,
        udot_max=udot_max,
        decay=decay,
        max_udot=max_udot,
        max_udot_capped=False,
        decay_rate=rate,
        P=_frozen(P) if holds else None,
        margins=margins,
        solver=solver,
        status=status,
        details=dict(details),
    )


def _lipschitz(
    params: BoucWenParams, sc: _Scaled, udot_max: float, decay: float
) -> TierCertificate:
    c = _lipschitz_coefficient(params)
    alpha0 = -sc.spectral_abscissa()
    return _lmi_tier(
        "lipschitz",
        lambda v, m: _check_lipschitz(sc, c * v, m),
        udot_max=udot_max,
        decay=decay,
        cap=_search_cap(params),
        decay_cap=lambda v: alpha0,
        details={"L": c * udot_max},
    )


def _sector(params: BoucWenParams, sc: _Scaled, udot_max: float, decay: float) -> TierCertificate:
    def cap_at(v: float) -> float:
        return -max(sc.spectral_abscissa(k) for k in sector_interval(params, v))

    k_lo, k_hi = sector_interval(params, udot_max)
    return _lmi_tier(
        "sector",
        lambda v, m: _check_sector(sc, *sector_interval(params, v), m),
        udot_max=udot_max,
        decay=decay,
        cap=_search_cap(params),
        decay_cap=cap_at,
        details={"k_interval": [k_lo, k_hi]},
    )


def _sampled(
    params: BoucWenParams, K: np.ndarray, udot_max: float, decay: float, dt: float
) -> TierCertificate:
    sp = _prepare_sampled(params, K, dt)
    c = _lipschitz_coefficient(params)
    cap = min(_search_cap(params), 50.0 / (c * dt)) if c > 0 else math.inf

    def check(v: float, m: float) -> _Check:
        lo, hi = rho_interval(params, v, dt)
        return _check_sampled(sp, lo, hi, math.exp(-m * dt))

    def every_rate(m: float) -> _Check:
        # beta >= |gamma|: rho in [exp(-(beta + |gamma|) v dt), 1] within [0, 1] for every v
        return _check_sampled(sp, 0.0, 1.0, math.exp(-m * dt))

    def decay_cap(v: float) -> float:
        radii = []
        for rho in rho_interval(params, v, dt):
            if not math.isfinite(rho):
                return 0.0
            Ad = sp.IKC_F.copy()
            Ad[:, 2] *= rho
            radii.append(float(np.max(np.abs(np.linalg.eigvals(_similar(Ad, sp.s))))))
        rmax = max(radii)
        return -math.log(rmax) / dt if 0 < rmax < 1 else (math.inf if rmax == 0 else 0.0)

    def capped_decay(v: float) -> float:
        cap_v = decay_cap(v)
        return cap_v if math.isfinite(cap_v) else 50.0 / dt

    rho_lo, rho_hi = rho_interval(params, udot_max, dt)
    return _lmi_tier(
        "sampled",
        check,
        udot_max=udot_max,
        decay=decay,
        cap=cap,
        decay_cap=capped_decay,
        details={
            "dt": dt,
            "rho_interval": [rho_lo, rho_hi],
            "discrete_gains": [float(x) for x in K],
            "r": math.exp(-decay * dt),
        },
        every_rate=every_rate if params.beta >= abs(params.gamma) else None,
    )


_CONTINUOUS_TIERS = {"theorem1": _theorem1, "lipschitz": _lipschitz, "sector": _sector}


# -- public entry points ---------------------------------------------------------------


def certify(
    params: BoucWenParams,
    gains: Sequence[float],
    *,
    udot_max: float,
    decay: float = 0.0,
    dt: float | None = None,
    tiers: Sequence[str] | None = None,
    allow_unbounded: bool = False,
) -> CertificateReport:
    """Certify observer gains for an input-rate envelope, tier by tier.

    Parameters
    ----------
    params : BoucWenParams
        The stage.
    gains : sequence of 3 floats
        Continuous observer gains ``(l1, l2, l3)`` (1/s, 1/s^2, 1/s).
    udot_max : float
        Bound on ``|u'|`` (V/s), > 0.
    decay : float
        Required exponential decay rate of the estimation error (1/s), >= 0.
    dt : float, optional
        Sample time (s); adds the ``sampled`` tier for the predict/update
        observer with the pole-matched discrete gain
        :func:`bwdesign.observers.discrete_gains`.
    tiers : sequence of str, optional
        Compute only these tiers (names from :data:`TIERS`); default all
        (``sampled`` only when ``dt`` is given).
    allow_unbounded : bool
        Accept a model outside the bounded Bouc-Wen class.

    Returns
    -------
    CertificateReport
        One :class:`TierCertificate` per tier. Solver trouble is a status in
        the report, never an exception.

    Raises
    ------
    GainError
        Malformed gains, or gains violating the paper's Hurwitz conditions (4).
    InputError
        ``udot_max``, ``decay`` or ``dt`` out of range.
    UnboundedModelError
        The model is outside the bounded class and ``allow_unbounded`` is False.

    Examples
    --------
    >>> from bwdesign import preset
    >>> rep = certify(preset("paper_experiment"), (8, 64, -512), udot_max=360.9)
    >>> rep.tier("theorem1").holds, rep.tier("sector").holds
    (False, True)
    """
    require_bounded(params, allow_unbounded)
    udot_max = _rate(udot_max, "udot_max (V/s)", positive=True)
    decay = _rate(decay, "decay (1/s)", positive=False)
    if dt is not None:
        dt = _check_dt(dt)
    gains = tuple(check_gains(params, gains).tolist())
    sc = _scale_continuous(params, error_matrix(params, gains))
    if tiers is None:
        wanted = TIERS if dt is not None else TIERS[:3]
    else:
        wanted = tuple(tiers) if not isinstance(tiers, str) else (tiers,)
        unknown = [t for t in wanted if t not in TIERS]
        if unknown:
            raise InputError(f"unknown tier(s) {unknown}; tiers are {', '.join(TIERS)}")
        if "sampled" in wanted and dt is None:
            raise InputError("the sampled tier needs the sample time dt (s)")
    certs = []
    for name in TIERS:
        if name in wanted and name != "sampled":
            certs.append(_CONTINUOUS_TIERS[name](params, sc, udot_max, decay))
    K = None
    if dt is not None:
        K = discrete_gains(params, gains, dt)
        if "sampled" in wanted:
            certs.append(_sampled(params, K, udot_max, decay, dt))
    return CertificateReport(
        params=params,
        gains=gains,
        udot_max=udot_max,
        decay=decay,
        dt=dt,
        discrete_gains=None if K is None else (float(K[0]), float(K[1]), float(K[2])),
        certificates=tuple(certs),
    )


def certify_discrete(
    params: BoucWenParams,
    K: Sequence[float],
    *,
    udot_max: float,
    dt: float,
    decay: float = 0.0,
    allow_unbounded: bool = False,
) -> CertificateReport:
    """The ``sampled`` tier alone, for a discrete update gain ``K``.

    Parameters
    ----------
    params : BoucWenParams
    K : sequence of 3 floats
        Discrete update gain of the predict/update observer.
    udot_max : float
        Bound on ``|u'|`` (V/s); per sample ``|du| <= udot_max dt``.
    dt : float
        Sample time (s).
    decay : float
        Required decay rate (1/s).

    Returns
    -------
    CertificateReport
        With ``gains = None`` and one certificate, ``sampled``.
    """
    require_bounded(params, allow_unbounded)
    udot_max = _rate(udot_max, "udot_max (V/s)", positive=True)
    decay = _rate(decay, "decay (1/s)", positive=False)
    dt = _check_dt(dt)
    Kv = np.asarray(_as_gains(K, "discrete gains K"))
    cert = _sampled(params, Kv, udot_max, decay, dt)
    return CertificateReport(
        params=params,
        gains=None,
        udot_max=udot_max,
        decay=decay,
        dt=dt,
        discrete_gains=(float(Kv[0]), float(Kv[1]), float(Kv[2])),
        certificates=(cert,),
    )


def default_pole_radius(params: BoucWenParams, dt: float | None = None) -> float:
    """Default pole-disk radius (rad/s) for :func:`synthesize`.

    ``10 sqrt(a1)`` (ten times the stage's natural frequency), and at most
    ``1/dt`` when a sample time is given, so that ``|lambda| dt <= 1``.
    """
    R = 10.0 * math.sqrt(params.a1)
    if dt is not None:
        R = min(R, 1.0 / dt)
    return R


def synthesize(
    params: BoucWenParams,
    *,
    udot_max: float,
    decay: float = 0.0,
    pole_radius: float | None = None,
    dt: float | None = None,
    allow_unbounded: bool = False,
) -> SynthesisResult:
    """Observer gains certified for ``|u'| <= udot_max`` with at least ``decay``.

    Without ``dt`` the ``sector`` LMI is solved in ``(P, Y = P l)`` with the
    observer poles in the disk ``|s| < pole_radius``. With ``dt`` the discrete
    ``sampled`` LMI is solved in ``(P, Y = P K)`` directly, with the nominal
    discrete poles in the disk ``|z - 1| < 1 - exp(-pole_radius dt)`` (the
    image of the continuous disk near ``z = 1``; it keeps every pole off the
    negative real axis, so the exact continuous equivalent of ``K`` exists and
    is reported as ``gains``). The LMI is solved twice: first for the largest
    margin ``t*`` (whose optimal set is not a single point), then for the
    smallest ``||Y||^2 + 0.01 ||P||_F^2`` with margin ``t*/2``: the least
    aggressive gains that keep half the best margin, a unique and reproducible
    design. Either way the result is re-certified by :func:`certify` before it
    is called feasible.

    Parameters
    ----------
    params : BoucWenParams
    udot_max : float
        Input-rate bound (V/s), > 0.
    decay : float
        Required decay rate (1/s), >= 0.
    pole_radius : float, optional
        Pole-disk radius (rad/s); default :func:`default_pole_radius`.
    dt : float, optional
        Sample time (s): synthesise the sampled observer.
    allow_unbounded : bool
        Accept a model outside the bounded class.

    Returns
    -------
    SynthesisResult
        ``feasible`` with gains and the re-certification, or ``feasible =
        False`` with ``binding`` naming the requirement that cannot be met and
        ``reason`` saying so in one sentence.

    Raises
    ------
    InputError
        ``udot_max``, ``decay``, ``pole_radius`` or ``dt`` out of range.

    Examples
    --------
    >>> from bwdesign import preset
    >>> res = synthesize(preset("paper_experiment"), udot_max=400.0, decay=50.0)
    >>> res.feasible
    True
    """
    require_bounded(params, allow_unbounded)
    udot_max = _rate(udot_max, "udot_max (V/s)", positive=True)
    decay = _rate(decay, "decay (1/s)", positive=False)
    if dt is not None:
        dt = _check_dt(dt)
    R = (
        default_pole_radius(params, dt)
        if pole_radius is None
        else _rate(pole_radius, "pole_radius (rad/s)", positive=True)
    )
    if dt is None:
        return _synthesize_continuous(params, udot_max, decay, R, allow_unbounded)
    return _synthesize_sampled(params, udot_max, decay, R, dt, allow_unbounded)


@dataclass(frozen=True)
class _Attempt:
    ok: bool
    sol: Any
    t: float | None


def _attempt(sol: Any) -> _Attempt:
    t = float(sol["t"]) if sol.ok else None
    return _Attempt(bool(sol.ok and t is not None and t > 0), sol, t)


def _diagnose(
    params: BoucWenParams,
    attempt: Callable[[float, float, bool], _Attempt],
    *,
    tier: str,
    udot_max: float,
    decay: float,
    R: float,
    dt: float | None,
    first: _Attempt,
) -> SynthesisResult:
    """Name the binding requirement of an infeasible request."""
    common = dict(
        feasible=False,
        tier=tier,
        gains=None,
        discrete_gains=None,
        udot_max=udot_max,
        decay=decay,
        pole_radius=R,
        dt=dt,
        margin=first.t,
        solver=first.sol.solver,
        status=first.sol.status,
        report=None,
        params=params,
    )
    if not first.sol.ok and not isinstance(first.sol, _NoSolve):
        return SynthesisResult(
            binding="solver",
            reason=(
                f"the {tier} synthesis LMI was not solved ({'; '.join(first.sol.attempts)}); "
                "no gains are certified"
            ),
            max_decay=None,
            max_udot=None,
            **common,
        )
    where = f"within pole radius {R:g} rad/s at |u'| <= {udot_max:g} V/s ({tier} tier)"
    if decay > 0 and attempt(udot_max, 0.0, True).ok:
        cap = decay
        max_decay = _largest_decay(lambda m: attempt(udot_max, m, True).ok, cap)
        free = attempt(udot_max, decay, False).ok
        reason = (
            f"decay {decay:g} 1/s is not reachable {where}; the largest certifiable decay "
            f"there is {max_decay:.4g} 1/s"
        )
        if free:
            reason += "; without the pole region it is reachable, so a larger pole radius may help"
        return SynthesisResult(
            binding="pole_radius" if free else "decay",
            reason=reason,
            max_decay=max_decay,
            max_udot=None,
            **common,
        )
    cap = _search_cap(params)
    if dt is not None and _lipschitz_coefficient(params) > 0:
        cap = min(cap, 50.0 / (_lipschitz_coefficient(params) * dt))
    max_udot, _ = _largest_rate(lambda v: attempt(v, 0.0, True).ok, udot_max, min(cap, udot_max))
    if attempt(udot_max, 0.0, False).ok:
        return SynthesisResult(
            binding="pole_radius",
            reason=(
                f"no gains with poles within radius {R:g} rad/s certify |u'| <= {udot_max:g} V/s "
                f"({tier} tier; the largest certifiable within that radius is {max_udot:.4g} V/s); "
                "without the pole region they exist, so raise the pole radius"
            ),
            max_decay=None,
            max_udot=max_udot,
            **common,
        )
    return SynthesisResult(
        binding="udot_max",
        reason=(
            f"|u'| <= {udot_max:g} V/s cannot be certified by any gains at the {tier} tier "
            f"(within pole radius {R:g} rad/s the largest certifiable is {max_udot:.4g} V/s)"
        ),
        max_decay=None,
        max_udot=max_udot,
        **common,
    )


def _synthesize_continuous(
    params: BoucWenParams, udot_max: float, decay: float, R: float, allow_unbounded: bool
) -> SynthesisResult:
    from . import lmi

    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    A0h = _similar(_model_matrix(params), T) / w
    Ch = _C * T

    def attempt(v: float, m: float, disk: bool, t_min: float | None = None) -> _Attempt:
        k_lo, k_hi = sector_interval(params, v)
        sol = lmi.sector_synthesis(
            A0h,
            Ch,
            k_lo=k_lo / w,
            k_hi=k_hi / w,
            mu=m / w,
            radius=R / w if disk else None,
            t_min=t_min,
        )
        return _attempt(sol)

    first = attempt(udot_max, decay, True)
    if not first.ok:
        return _diagnose(
            params,
            attempt,
            tier="sector",
            udot_max=udot_max,
            decay=decay,
            R=R,
            dt=None,
            first=first,
        )
    design = _refine(first, lambda t_min: attempt(udot_max, decay, True, t_min))
    P = np.asarray(design.sol["P"])
    lh = np.linalg.solve((P + P.T) / 2, np.asarray(design.sol["Y"]).ravel())
    gains = tuple(float(x) for x in w * T * lh)
    return _finish(params, first, gains, None, "sector", udot_max, decay, R, None, allow_unbounded)


def _synthesize_sampled(
    params: BoucWenParams, udot_max: float, decay: float, R: float, dt: float, allow_unbounded: bool
) -> SynthesisResult:
    from . import lmi

    w = math.sqrt(params.a1)
    T = np.array([1.0, w, 1.0])
    F = np.array(discretize(params, dt).F)
    Fh = _similar(F, T)
    Hh = F[0] * T
    disk = (1.0, -math.expm1(-R * dt))

    def attempt(v: float, m: float, with_disk: bool, t_min: float | None = None) -> _Attempt:
        lo, hi = rho_interval(params, v, dt)
        if not math.isfinite(hi):
            return _Attempt(False, _NoSolve(), None)
        sol = lmi.sampled_synthesis(
            Fh,
            Hh,
            rho_lo=lo,
            rho_hi=hi,
            r=math.exp(-m * dt),
            disk=disk if with_disk else None,
            t_min=t_min,
        )
        return _attempt(sol)

    first = attempt(udot_max, decay, True)
    if not first.ok:
        return _diagnose(
            params, attempt, tier="sampled", udot_max=udot_max, decay=decay, R=R, dt=dt, first=first
        )
    design = _refine(first, lambda t_min: attempt(udot_max, decay, True, t_min))
    P = np.asarray(design.sol["P"])
    Kh = np.linalg.solve((P + P.T) / 2, np.asarray(design.sol["Y"]).ravel())
    K = tuple(float(x) for x in T * Kh)
    gains = continuous_equivalent(params, K, dt)
    return _finish(params, first, gains, K, "sampled", udot_max, decay, R, dt, allow_unbounded)


#: The refinement keeps this fraction of the best synthesis margin.
REFINE_MARGIN_FRACTION = 0.5


def _refine(first: _Attempt, solve: Callable[[float], _Attempt]) -> _Attempt:
    """Second stage: the smallest gains keeping half the best margin (a unique point).

    Falls back to the max-margin design if the refinement is not solved.
    """
    refined = solve(REFINE_MARGIN_FRACTION * float(first.t))
    return refined if refined.sol.ok else first


class _NoSolve:
    """Stand-in solution for a request that needs no solver to say no."""

    ok = False
    status = "not_solved"
    solver = ""
    attempts = ("rho interval unbounded at this rate",)


#: Synthesised gains are rounded to this many significant digits before re-certification.
SIGNIFICANT_DIGITS = 7


def _round_sig(values: tuple[float, ...] | None) -> tuple[float, ...] | None:
    if values is None:
        return None
    return tuple(float(f"{v:.{SIGNIFICANT_DIGITS}g}") for v in values)


def _finish(
    params: BoucWenParams,
    first: _Attempt,
    gains: tuple[float, float, float] | None,
    K: tuple[float, float, float] | None,
    tier: str,
    udot_max: float,
    decay: float,
    R: float,
    dt: float | None,
    allow_unbounded: bool,
) -> SynthesisResult:
    # Round to SIGNIFICANT_DIGITS before re-certifying: the certificate is then
    # about exactly the numbers reported (and pasted into firmware), and the
    # solver's last-digit noise does not reach the report.
    gains = _round_sig(gains)
    K = _round_sig(K)
    report: CertificateReport | None = None
    problem = ""
    if gains is not None:
        try:
            report = certify(
                params,
                gains,
                udot_max=udot_max,
                decay=decay,
                dt=dt,
                allow_unbounded=allow_unbounded,
            )
        except GainError as err:
            problem = str(err)
    if report is None and K is not None:
        report = certify_discrete(
            params, K, udot_max=udot_max, dt=dt, decay=decay, allow_unbounded=allow_unbounded
        )
    holds = report is not None and report.tier(tier).holds
    if report is not None and report.discrete_gains is not None:
        K = report.discrete_gains
    if holds:
        what = f"gains l = ({', '.join(f'{g:.6g}' for g in gains)})" if gains else "discrete gains"
        reason = (
            f"{what} certified by the {tier} tier for |u'| <= {udot_max:g} V/s with decay "
            f">= {decay:g} 1/s, poles within {R:g} rad/s"
        )
        if tier == "sampled" and gains is None:
            reason += "; the discrete poles have no exact continuous equivalent"
    else:
        reason = "the synthesised gains did not pass re-certification" + (
            f": {problem}" if problem else f" ({report.tier(tier).status})" if report else ""
        )
    return SynthesisResult(
        feasible=holds,
        tier=tier,
        gains=gains,
        discrete_gains=K,
        udot_max=udot_max,
        decay=decay,
        pole_radius=R,
        dt=dt,
        binding=None if holds else "verification",
        reason=reason,
        max_decay=None,
        max_udot=None,
        margin=first.t,
        solver=first.sol.solver,
        status=first.sol.status,
        report=report,
        params=params,
    )
