"""Synthesis per tier (a study part): the largest envelope synthesised gains reach.

For each tier (``theorem1``, ``lipschitz``, ``sector`` and, with a sample time,
``sampled``) :func:`synthesize_per_tier` asks :func:`bwdesign.synthesize` for
gains of that tier at the stage's synthesis decay and reports the envelope
``|u'|`` (input unit/s) those gains are certified to reach for that tier:

``theorem1``, ``lipschitz``
    Their LMIs already maximise the envelope (``theorem1`` minimises ``||X||``
    in the scaled norm, independent of the requested ``|u'|``; ``lipschitz``
    bisects on the Lipschitz constant), so one synthesis at the stage's
    envelope answers. When the answer is below the stage's envelope the
    synthesis is a "no" and hides its gains; a second synthesis at half the
    envelope it reported returns them (the same LMI, so the same gains).
``sector``, ``sampled``
    These synthesise for a given ``|u'|``: gains asked for a larger rate reach
    a larger envelope. Unless the first answer is already every rate (``inf``),
    the requested rate is searched: first to the envelope the gains synthesised
    at the stage's rate reach (when beyond 4 times it), then times 4 until the
    synthesis fails (down by 4 from an infeasible start), then bisected to
    :data:`SEARCH_RTOL`. The row
    is the best envelope found among the feasible syntheses: a lower bound on
    what gains chosen for the tier can certify (feasibility need not be
    monotone in the requested rate, so the search can miss a larger one).

Every envelope is the re-certification's own number (:func:`bwdesign.certify`,
outside the solver), never the synthesis LMI's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..certify.results import SynthesisResult
from ..design.gains import synthesize
from ..model.params import BoucWenParams

__all__ = ["TierSynthesis", "synthesize_per_tier", "search_requested_rate", "SEARCH_RTOL"]

#: Relative resolution of the search over the requested |u'| (sector, sampled).
SEARCH_RTOL = 0.05

#: Search limits: growth stops above ``udot_max * SEARCH_SPAN``, shrinking below it.
SEARCH_SPAN = 1e6


@dataclass(frozen=True)
class TierSynthesis:
    """One row of the per-tier synthesis table.

    Attributes
    ----------
    tier : str
    feasible : bool
        Synthesis for this tier succeeds at the stage's envelope ``udot_max``.
    gains : tuple of 3 floats or None
        Continuous gains (1/s, 1/s^2, 1/s) that reach ``envelope``; None when no
        synthesis of the tier succeeded at any requested rate.
    discrete_gains : tuple of 3 floats or None
        Their discrete update gain ``K`` (sampled tier only).
    envelope : float
        Largest ``|u'|`` (input unit/s) the tier certifies for ``gains`` with at
        least ``decay``; ``inf`` for every rate, 0 when there are no gains.
    decay : float
        Required decay rate (1/s).
    requested : float or None
        The ``|u'|`` (input unit/s) the synthesis of ``gains`` was asked for.
    searched : bool
        The requested rate was searched (sector, sampled with a finite first answer).
    syntheses : int
        Number of :func:`bwdesign.synthesize` calls behind the row.
    reason : str
        The synthesis of ``gains`` in one sentence (without gains: why the
        synthesis at the stage's envelope failed).
    theorem1_unscaled : float or None
        ``theorem1`` only: what :func:`bwdesign.certify`'s ``theorem1`` tier
        (the paper's unscaled norm) certifies for the same gains (input unit/s).
    """

    tier: str
    feasible: bool
    gains: tuple[float, float, float] | None
    discrete_gains: tuple[float, float, float] | None
    envelope: float
    decay: float
    requested: float | None
    searched: bool
    syntheses: int
    reason: str
    theorem1_unscaled: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "tier": self.tier,
            "feasible": self.feasible,
            "gains": None if self.gains is None else list(self.gains),
            "discrete_gains": None if self.discrete_gains is None else list(self.discrete_gains),
            "envelope": self.envelope,
            "envelope_unbounded": math.isinf(self.envelope),
            "decay": self.decay,
            "requested_udot_max": self.requested,
            "searched": self.searched,
            "syntheses": self.syntheses,
            "reason": self.reason,
            "theorem1_unscaled_envelope": self.theorem1_unscaled,
        }


def _envelope(res: SynthesisResult, tier: str) -> float:
    """The envelope a feasible synthesis' gains reach for ``tier`` (0 when not feasible)."""
    if not res.feasible:
        return 0.0
    if tier == "theorem1":  # the scaled-norm envelope checked outside the solver
        return float(res.max_udot)
    return float(res.report.tier(tier).max_udot)


def synthesize_per_tier(
    params: BoucWenParams,
    *,
    udot_max: float,
    decay: float,
    dt: float | None = None,
    pole_radius: float | None = None,
    allow_unbounded: bool = False,
) -> list[TierSynthesis]:
    """Synthesise gains for every tier and the envelope they reach (see the module doc).

    Parameters
    ----------
    params : BoucWenParams
    udot_max : float
        The stage's envelope (input unit/s): where "feasible" is asked and the
        search starts.
    decay : float
        Required decay rate (1/s) of every synthesis and envelope.
    dt : float, optional
        Sample time (s); the ``sampled`` tier only with it.
    pole_radius : float, optional
        Pole-disk radius (rad/s) of the sector and sampled syntheses (default
        :func:`bwdesign.design.default_pole_radius`).
    allow_unbounded : bool

    Returns
    -------
    list of TierSynthesis
        In the order theorem1, lipschitz, sector[, sampled].
    """
    tiers = ("theorem1", "lipschitz", "sector") + (("sampled",) if dt is not None else ())
    rows = []
    for tier in tiers:

        def run(u: float, tier: str = tier, explain: bool = True) -> SynthesisResult:
            return synthesize(
                params,
                udot_max=u,
                decay=decay,
                pole_radius=pole_radius,
                dt=dt,
                allow_unbounded=allow_unbounded,
                tier=tier,
                explain=explain,
            )

        def probe(u: float, tier: str = tier) -> SynthesisResult:
            # a search step's "no" is never shown (a row's reason is its first
            # synthesis' or its best's), so it is not explained
            return run(u, tier, explain=False)

        first = run(udot_max)
        tried = [(udot_max, first)]
        searched = False
        if tier in ("theorem1", "lipschitz"):
            if not first.feasible and first.max_udot and first.max_udot > 0:
                half = 0.5 * float(first.max_udot)
                tried.append((half, run(half)))
        elif not math.isinf(_envelope(first, tier)):
            searched = True
            tried += search_requested_rate(
                probe, udot_max, first.feasible, jump=_envelope(first, tier)
            )
        best_u, best = max(tried, key=lambda ur: _envelope(ur[1], tier))
        ok = best.feasible
        unscaled = None
        if tier == "theorem1" and ok and best.report is not None:
            unscaled = float(best.report.tier("theorem1").max_udot)
        rows.append(
            TierSynthesis(
                tier=tier,
                feasible=first.feasible,
                gains=best.gains if ok else None,
                discrete_gains=best.discrete_gains if ok else None,
                envelope=_envelope(best, tier),
                decay=float(decay),
                requested=best_u if ok else None,
                searched=searched,
                syntheses=len(tried),
                reason=best.reason if ok else first.reason,
                theorem1_unscaled=unscaled,
            )
        )
    return rows


def search_requested_rate(
    run: Any, start: float, feasible: bool, *, jump: float = 0.0
) -> list[tuple[float, SynthesisResult]]:
    """Syntheses along the requested rate: x4 steps to the edge of feasibility, then bisection.

    ``jump``: the envelope the gains synthesised at ``start`` reach; the first step up
    goes there when it is beyond ``4 start`` (gains asked for their own envelope).
    """
    tried = []
    if feasible:
        lo, hi = start, None
        while hi is None and lo < start * SEARCH_SPAN:
            u = max(4.0 * lo, jump) if not tried else 4.0 * lo
            res = run(u)
            tried.append((u, res))
            if res.feasible:
                lo = u
            else:
                hi = u
    else:
        lo, hi = None, start
        while lo is None and hi > start / SEARCH_SPAN:
            u = hi / 4.0
            res = run(u)
            tried.append((u, res))
            if res.feasible:
                lo = u
            else:
                hi = u
    if lo is None or hi is None:
        return tried
    while hi / lo > 1.0 + SEARCH_RTOL:
        u = math.sqrt(lo * hi)
        res = run(u)
        tried.append((u, res))
        if res.feasible:
            lo = u
        else:
            hi = u
    return tried
