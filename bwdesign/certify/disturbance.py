"""Certificates for the disturbance hysteresis observer (PHDO): its *lumped* error.

What is certified, and nothing more
-----------------------------------
The PHDO (:class:`bwdesign.DisturbanceHysteresisObserver`) estimates
``(x1, x2, x3, d)`` from ``y = x1``; its linear part sees only ``w = x3 + d``.
With the error ``e = x - xhat`` (true ``d = 0``, or the disturbance the model
error creates) the coordinates used here are::

    xi = (e1, e2, ew, eta),   ew = e3 + ed,   eta = e3 - c ew,   c = l3 / (l3 + l4)

``eta`` is the combination the innovation never moves. In them the error is::

    continuous:  xi' = (blockdiag(A_o, 0) + k B) xi,          k in [k_lo, k_hi]
    sampled:     xi+ = blockdiag(Phi_o, 1) (I + (rho - 1) B') xi,  rho in [rho_lo, rho_hi]

with ``A_o = A0 - (l1, l2, l3 + l4) C`` (the PHSO's error matrix with the lumped
gain), ``Phi_o = (I - K_o C) F``, the hysteresis mismatch
``phi(u', x3) - phi(u', x3hat) = -k e3`` (sector of
:func:`bwdesign.certify.sector_interval`) or the jump-map slope ``rho``
(:func:`bwdesign.certify.rho_interval`), and
``B = -(e_w + (1 - c) e_eta)(c e_w + e_eta)'`` (``B' = -B``).

At ``k = 0`` (``rho = 1``: the input does not move) ``eta`` is frozen and
decoupled: no Lyapunov function can decrease along it. The certificate is
therefore a block-diagonal ``P = blockdiag(P_o, p)`` with::

    He(P A(k)) <= -eps diag(1, 1, 1, 0)      (continuous, both ends of the sector)
    A_d(rho)' P A_d(rho) - P <= -eps diag(1, 1, 1, 0)   (sampled, both ends of rho)

(affine in ``k``, resp. convex in ``A_d``, so the two ends cover the interval),
checked outside the solver as strict inequalities: the 3x3 observable block at
the degenerate end, the full 4x4 at the others. It proves, for every input with
``|u'| <= udot_max``:

- ``V = xi' P xi`` never increases, so ``e3`` and ``ed`` stay bounded;
- the lumped error ``(e1, e2, e3 + ed)`` is square-summable and converges to 0
  (``sum |xi_o|^2 <= V(0)/eps``; Barbalat in continuous time);
- **not** that ``e3`` and ``ed`` converge separately: they do only while the
  hysteresis contracts (``k > 0``, ``rho < 1``) often enough; with a held input they
  stay where they are. No exponential rate is claimed for the same reason.

When ``beta < |gamma|`` the sector (``rho``) interval contains expanding values
(``k_lo < 0``, ``rho_hi > 1``): ``eta`` can grow there and the check fails, as it
should.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams
from ..model.plant import check_dt, discretize
from ..observers.gains import (
    check_disturbance_discrete,
    check_disturbance_gains,
    disturbance_discrete_gains,
    error_matrix,
)
from ..validate import DECAY, UDOT_BOUND, Range, real
from .checks import negdef, posdef, rho_interval, sector_interval
from .results import Margin

__all__ = [
    "LumpedCertificate",
    "certify_disturbance",
    "verify_disturbance",
    "synthesize_disturbance",
]

_EW, _ETA = 2, 3
#: Nominal decay rate a synthesis aims for (1/s): :data:`~bwdesign.validate.DECAY` without 0.
POSITIVE_DECAY = Range(0.0, DECAY.hi, lo_open=True, unit=DECAY.unit)


@dataclass(frozen=True)
class LumpedCertificate:
    """A certificate for the PHDO's lumped error (see the module docstring for the claim).

    Attributes
    ----------
    tier : str
        ``"sector"`` (continuous observer) or ``"sampled"`` (the observer at ``dt``).
    holds : bool
        The solver's ``P`` passed every outside check.
    udot_max : float
        Input-rate bound (input unit/s).
    claim : str
        What ``holds`` proves, in words.
    P : ndarray, shape (4, 4) or None
        ``blockdiag(P_o, p)`` in the coordinates ``(e1, e2, e3 + ed, e3 - c (e3 + ed))``.
    split : float
        ``c = l3 / (l3 + l4)`` (``k3 / (k3 + k4)`` for discrete gains).
    interval : tuple of 2 floats
        The sector ``(k_lo, k_hi)`` (1/s) or the jump-slope interval ``(rho_lo, rho_hi)``.
    margins : tuple of Margin
        The inequalities checked outside the solver.
    solver, status : str
    """

    tier: str
    holds: bool
    udot_max: float
    claim: str
    P: np.ndarray | None
    split: float
    interval: tuple[float, float]
    margins: tuple[Margin, ...] = field(default_factory=tuple)
    solver: str = ""
    status: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "tier": self.tier,
            "holds": self.holds,
            "udot_max": self.udot_max,
            "claim": self.claim,
            "P": None if self.P is None else self.P.tolist(),
            "split": self.split,
            "interval": list(self.interval),
            "margins": [m.to_dict() for m in self.margins],
            "solver": self.solver,
            "status": self.status,
        }


def _B(c: float) -> np.ndarray:
    """``-(e_w + (1 - c) e_eta)(c e_w + e_eta)'``."""
    left = np.zeros(4)
    left[_EW], left[_ETA] = 1.0, 1.0 - c
    right = np.zeros(4)
    right[_EW], right[_ETA] = c, 1.0
    return -np.outer(left, right)


def _embed(M3: np.ndarray, corner: float) -> np.ndarray:
    M = np.zeros((4, 4))
    M[:3, :3] = M3
    M[3, 3] = corner
    return M


@dataclass(frozen=True)
class _Problem:
    tier: str
    A_o: np.ndarray  # continuous A_o or discrete Phi_o
    c: float
    ends: tuple[float, float]  # (k_lo, k_hi) or (rho_lo, rho_hi)
    discrete: bool

    def vertex(self, v: float) -> np.ndarray:
        if self.discrete:
            return _embed(self.A_o, 1.0) @ (np.eye(4) - (v - 1.0) * _B(self.c))
        return _embed(self.A_o, 0.0) + v * _B(self.c)

    @property
    def degenerate(self) -> float:
        return 1.0 if self.discrete else 0.0

    def split_ends(self) -> tuple[bool, list[float]]:
        """Whether the degenerate value is an end, and the other ends."""
        deg = self.degenerate
        ends = sorted(set(self.ends))
        return deg in ends, [v for v in ends if v != deg]


def _problem(
    params: BoucWenParams, gains: Any, udot_max: float, dt: float | None, discrete_K: Any
) -> _Problem:
    if not isinstance(params, BoucWenParams):
        raise InputError(f"params must be a BoucWenParams, got {type(params).__name__}")
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_BOUND)
    if dt is None:
        if discrete_K is not None:
            raise InputError("discrete gains K need dt (the sampled tier)")
        l1, l2, l3, l4 = check_disturbance_gains(params, gains)
        lw = l3 + l4
        A_o = error_matrix(params, (l1, l2, lw))
        return _Problem("sector", A_o, l3 / lw, sector_interval(params, udot_max), False)
    dt = check_dt(dt)
    if (gains is None) == (discrete_K is None):
        raise InputError("give either continuous gains (l1, l2, l3, l4) or discrete=K")
    if discrete_K is None:
        K = disturbance_discrete_gains(params, gains, dt)
    else:
        K = check_disturbance_discrete(discrete_K)
    kw = K[2] + K[3]
    F = np.array(discretize(params, dt).F)
    Ko = np.array([K[0], K[1], kw])
    Phi_o = F - np.outer(Ko, F[0])
    return _Problem("sampled", Phi_o, K[2] / kw, rho_interval(params, udot_max, dt), True)


def _scale(params: BoucWenParams) -> np.ndarray:
    """``z = S xi`` with ``S = diag(1, 1/sqrt(a1), 1, 1)`` (x2 in displacement units)."""
    return np.array([1.0, 1.0 / math.sqrt(params.a1), 1.0, 1.0])


def _check(pr: _Problem, P: np.ndarray) -> tuple[Margin, ...]:
    """The outside check of ``P`` (original coordinates) at every end of the interval."""
    P = (P + P.T) / 2
    margins = [posdef("P > 0", P)]
    off = float(np.max(np.abs(P[:3, 3]))) if P.shape == (4, 4) else math.inf
    scale = float(np.max(np.abs(np.diag(P))))
    margins.append(Margin("P block diagonal (|P[:3, 3]| / max |P_ii|)", off / scale, 1e-12))
    has_deg, others = pr.split_ends()
    name = "rho" if pr.discrete else "k"
    unit = "" if pr.discrete else " 1/s"
    Po = P[:3, :3]
    if has_deg:
        A = pr.A_o
        M = A.T @ Po @ A - Po if pr.discrete else A.T @ Po + Po @ A
        what = "Phi_o' P_o Phi_o - P_o" if pr.discrete else "He(P_o A_o)"
        margins.append(negdef(f"{what} < 0 at {name} = {pr.degenerate:g}", M))
    for v in others:
        A = pr.vertex(v)
        M = A.T @ P @ A - P if pr.discrete else A.T @ P + P @ A
        what = "A_d' P A_d - P" if pr.discrete else "He(P A)"
        margins.append(negdef(f"{what} < 0 at {name} = {v:.6g}{unit}", M))
    return tuple(margins)


def _claim(pr: _Problem, udot_max: float) -> str:
    where = "the sampled observer" if pr.discrete else "the continuous observer"
    return (
        f"{where}: for every input with |u'| <= {udot_max:.6g} the lumped error "
        "(x1, x2, x3 + d) converges to 0 (V = xi' P xi never increases and bounds the sum "
        "of its squares) and the hysteresis and disturbance errors stay bounded; x3 and d "
        "converge separately only while the hysteresis contracts (the input moves)"
    )


def certify_disturbance(
    params: BoucWenParams,
    gains: Any = None,
    *,
    udot_max: float,
    dt: float | None = None,
    discrete: Any = None,
) -> LumpedCertificate:
    """Certify the PHDO's lumped error over ``|u'| <= udot_max``.

    Parameters
    ----------
    params : BoucWenParams
    gains : array_like, shape (4,), optional
        Continuous gains ``(l1, l2, l3, l4)``.
    udot_max : float
        Input-rate bound (input unit/s).
    dt : float, optional
        Sample time (s): the ``sampled`` tier (the discrete error map with the
        hysteresis jump slope); without it the ``sector`` tier (continuous).
    discrete : array_like, shape (4,), optional
        Discrete gains ``K`` instead of ``gains`` (sampled tier only).

    Returns
    -------
    LumpedCertificate
        ``holds`` only when the solver's ``P`` passed the outside check; solver
        trouble is a status, never a certificate.
    """
    from . import lmi

    pr = _problem(params, gains, udot_max, dt, discrete)
    s = _scale(params)
    sim = s[:, None] / s[None, :]  # S A S^-1
    w = 1.0 if pr.discrete else math.sqrt(params.a1)  # time in 1/sqrt(a1)
    has_deg, others = pr.split_ends()
    A_o = pr.A_o * sim[:3, :3] / w if has_deg else None
    verts = [pr.vertex(v) * sim / w for v in others]
    sol = lmi.lumped_margin(A_o, verts, discrete=pr.discrete)
    interval = (float(pr.ends[0]), float(pr.ends[1]))
    base = dict(
        tier=pr.tier,
        udot_max=float(udot_max),
        claim=_claim(pr, udot_max),
        split=float(pr.c),
        interval=interval,
        solver=sol.solver,
    )
    if not sol.ok:
        tried = "; ".join(sol.attempts) or "no solver ran"
        return LumpedCertificate(
            holds=False, P=None, status=f"solver failed: {sol.status} ({tried})", **base
        )
    t = float(sol["t"])
    if not t > 0:
        return LumpedCertificate(
            holds=False,
            P=None,
            status=f"not certified: the LMI has no strictly feasible point (t = {t:.3g} <= 0)",
            **base,
        )
    Ph = _embed(np.asarray(sol["Po"]), float(sol["p"]))
    P = Ph * np.outer(s, s)  # V = z' Ph z = xi' S Ph S xi
    margins = _check(pr, P)
    failed = [m.name for m in margins if not m.passed]
    if failed:
        return LumpedCertificate(
            holds=False,
            P=None,
            margins=margins,
            status="not certified: the solver's P failed the outside check ("
            + "; ".join(failed)
            + ")",
            **base,
        )
    return LumpedCertificate(holds=True, P=P, margins=margins, status="certified", **base)


def verify_disturbance(
    params: BoucWenParams,
    P: Any,
    gains: Any = None,
    *,
    udot_max: float,
    dt: float | None = None,
    discrete: Any = None,
) -> tuple[bool, tuple[Margin, ...]]:
    """Check a given ``P`` (4x4, coordinates of the module docstring) without a solver.

    Returns
    -------
    (bool, tuple of Margin)
        Whether every inequality holds, and the inequalities.
    """
    pr = _problem(params, gains, udot_max, dt, discrete)
    P = np.asarray(P, dtype=float)
    if P.shape != (4, 4) or not np.all(np.isfinite(P)):
        raise InputError(f"P must be a finite 4x4 matrix, got shape {P.shape}")
    margins = _check(pr, P)
    return all(m.passed for m in margins), margins


def synthesize_disturbance(
    params: BoucWenParams, *, udot_max: float, dt: float, decay: float = 100.0
) -> tuple[np.ndarray | None, LumpedCertificate | None, str]:
    """Discrete PHDO gains ``K = (k1, k2, 0, k4)`` by LMI synthesis, then certified.

    The split is ``l3 = 0`` (the whole lumped correction into ``d``, as the digital
    tuning's PHDO gains), which makes the program an LMI in ``(P_o, p, Y = P_o K_o)``
    (:func:`bwdesign.certify.lmi.lumped_sampled_synthesis`): the nominal observable
    part decays at least at ``decay`` (``r = exp(-decay dt)``) and the lumped-error
    certificate of the sampled tier holds at ``|u'| <= udot_max``. The gains are then
    re-certified from scratch by :func:`certify_disturbance` (solver and outside check):
    only that verdict counts.

    Parameters
    ----------
    params : BoucWenParams
    udot_max : float
        Input-rate bound (input unit/s).
    dt : float
        Sample time (s).
    decay : float
        Nominal decay rate of the observable error (1/s, > 0).

    Returns
    -------
    (K, certificate, reason)
        ``K`` (shape (4,)) and its certificate when certified, else ``(None, None or the
        failed certificate, reason)``.
    """
    from . import lmi

    dt = check_dt(dt)
    decay = real(decay, "decay (1/s)", within=POSITIVE_DECAY)
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_BOUND)
    rho_lo, rho_hi = rho_interval(params, udot_max, dt)
    if rho_hi > 1.0:
        return (
            None,
            None,
            (
                f"not synthesised: beta < |gamma| gives jump slopes up to {rho_hi:.6g} > 1 "
                "(the hysteresis error can grow); no lumped-error certificate exists"
            ),
        )
    s = _scale(params)[:3]
    F = np.array(discretize(params, dt).F)
    Fs = F * s[:, None] / s[None, :]
    hs = F[0] / s
    J = None if rho_lo == 1.0 else np.eye(4) - (rho_lo - 1.0) * _B(0.0)
    sol = lmi.lumped_sampled_synthesis(Fs, hs, J, r=math.exp(-decay * dt))
    if not sol.ok:
        return None, None, f"solver failed: {sol.status} ({'; '.join(sol.attempts)})"
    if not float(sol["t"]) > 0:
        return None, None, f"infeasible: no strictly feasible point (t = {float(sol['t']):.3g})"
    Ks = np.linalg.solve(np.asarray(sol["Po"]), np.asarray(sol["Y"]).ravel())
    Ko = Ks / s
    K = np.array([Ko[0], Ko[1], 0.0, Ko[2]])
    cert = certify_disturbance(params, udot_max=udot_max, dt=dt, discrete=K)
    if not cert.holds:
        return None, cert, f"the synthesised gains failed the re-certification: {cert.status}"
    margin_poles = np.abs(np.linalg.eigvals(F - np.outer(Ko, F[0])))
    if not margin_poles.max() <= math.exp(-decay * dt) * (1 + 1e-9):
        return (
            None,
            cert,
            (
                f"the synthesised gains miss the decay: pole radius {margin_poles.max():.6g} > "
                f"exp(-decay dt) = {math.exp(-decay * dt):.6g}"
            ),
        )
    return K, cert, "certified"
