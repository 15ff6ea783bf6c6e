"""Certificate result types: margins, tier certificates, reports, synthesis results."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model.params import BoucWenParams
from ..validate import Range

__all__ = [
    "TIERS",
    "Margin",
    "TierCertificate",
    "CertificateReport",
    "SynthesisResult",
    "RobustCertificate",
    "worst_margin",
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

#: The one sign convention of every :class:`Margin` (stated in its JSON).
MARGIN_SENSE = "passed means value < limit (slack = limit - value > 0)"

#: A contraction factor per sample of the robust certificates: ``0 < a < 1``.
CONTRACTION = Range(0.0, 1.0, lo_open=True, hi_open=True)

UNIT_ROUNDOFF = float(np.finfo(float).eps) / 2  # unit round-off
OUTPUT_ROW = np.array([1.0, 0.0, 0.0])


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
            "sense": MARGIN_SENSE,
            "slack": self.limit - self.value,
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
        the requested decay: for ``lipschitz``, ``sector`` and ``sampled`` the
        frequency-domain condition (circle criterion, see
        :mod:`bwdesign.certify.frequency`) backed off until a Lyapunov matrix passes
        the outside check there (at most 1e-6 below it for well-conditioned poles;
        :mod:`bwdesign.certify.verified`), so never above the exact envelope;
        closed form for ``theorem1``. 0 when nothing is certified (and when double
        precision cannot decide it: ``details["envelope_undecided"]``); ``inf`` when
        the tier is verified for every rate (``sampled`` with ``beta >= |gamma|``,
        where the jump-map slope stays in ``[0, 1]`` and the LMI holds on that
        whole interval).
    max_udot_capped : bool
        True when the tier was verified at the search limit only: the true envelope
        is at least ``max_udot`` (the criterion may hold for every rate).
    decay_rate : float or None
        The largest certified exponential rate ``mu`` (1/s) at ``udot_max``:
        ``||eps(t)|| <= c exp(-mu t) ||eps(0)||``; ``None`` when the tier does
        not hold (a tier that does not hold certifies no rate).
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
    decay_rate: float | None
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
    robust : RobustObserverCertificate or None
        The observer error over an uncertainty box
        (:func:`bwdesign.certify_robust_observer`), ``None`` without a box.
    """

    params: BoucWenParams
    gains: tuple[float, float, float] | None
    udot_max: float
    decay: float
    dt: float | None
    discrete_gains: tuple[float, float, float] | None
    certificates: tuple[TierCertificate, ...]
    robust: Any = None

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
        ``discrete_gains``, and ``robust`` when a box was given)."""
        out = {
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
        if self.robust is not None:  # only when asked for (documents without a box unchanged)
            out["robust"] = self.robust.to_dict()
        return out


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
        ``"solver"``; ``"unexplained"`` when ``synthesize(..., explain=False)`` did
        not look for it.
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
    pole_check : Margin or None
        The requested pole region measured on the returned gains, outside the
        solver (continuous: ``max |lambda|`` against the radius; sampled:
        ``max |z - 1|`` against ``1 - exp(-radius dt)``); ``feasible`` needs it
        to pass.
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
    pole_check: Margin | None = None

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
            "pole_check": None if self.pole_check is None else self.pole_check.to_dict(),
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


def frozen_array(a: np.ndarray) -> np.ndarray:
    """A read-only float copy of ``a``."""
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def worst_margin(margins: tuple[Margin, ...]) -> Margin | None:
    """The margin closest to its limit (the one a certificate's JSON quotes), or None."""
    return min(margins, key=lambda m: m.limit - m.value) if margins else None


@dataclass(frozen=True)
class RobustCertificate:
    """Robust convergence and steady error bounds of the sampled loop over a box.

    Attributes
    ----------
    holds : bool
        A common ``P`` passed the outside check at every corner, both ``rho`` ends
        and every interior sample.
    status : str
    decay : float or None
        Certified convergence rate of the error into the ellipsoid (1/s).
    tracking_bound, estimation_bound, x3_estimation_bound : float or None
        Certified steady bounds on ``|x1 - x_d|``, ``|x1hat - x1|`` and
        ``|x3hat - x3|`` (posterior) at the sample instants (length unit).
    a : float
        Contraction factor per sample used in the LMI.
    noise_max : float
        Sensor noise bound assumed (length unit).
    n_vertices, n_interior : int
    input_bounds : dict
        Bound of each exogenous channel (the reference channel per state).
    margins : tuple of Margin
        Smallest eigenvalue per checked block (passed when ``-min eig < 0``).
    solver : str
    details : dict
    """

    holds: bool
    status: str
    decay: float | None
    tracking_bound: float | None
    estimation_bound: float | None
    x3_estimation_bound: float | None
    a: float
    noise_max: float
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
            "tracking_bound": self.tracking_bound,
            "estimation_bound": self.estimation_bound,
            "x3_estimation_bound": self.x3_estimation_bound,
            "a": self.a,
            "noise_max": self.noise_max,
            "n_vertices": self.n_vertices,
            "n_interior": self.n_interior,
            "input_bounds": self.input_bounds,
            "worst_margin": None if worst is None else worst.to_dict(),
            "solver": self.solver,
            "details": self.details,
        }
