"""The closed loop simulated at every corner of an uncertainty box (one batch)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..control.loop import ClosedLoop
from ..model.references import Reference
from ..model.uncertainty import DisturbanceBound, UncertaintyBox
from .batch import BatchResult, simulate_batch

__all__ = ["simulate_corners", "simulate_plants", "disturbance_signals", "span"]


def disturbance_signals(bound: DisturbanceBound, t: np.ndarray) -> np.ndarray:
    """The worst-case input disturbances of a bound at the times ``t``, shape ``(4, len(t))``.

    ``+-input_max sin(2 pi f t)`` at the rate limit (``2 pi f input_max = rate_max``)
    and a ramp at ``+-rate_max`` from 0 to ``+-input_max``, then held (a constant
    ``+-input_max`` when ``rate_max = 0``).
    """
    dm, rate = bound.input_max, bound.rate_max
    t = np.asarray(t, dtype=float)
    if dm == 0:
        return np.zeros((4, t.size))
    sine = dm * np.sin(rate / dm * t)  # 2 pi f = rate_max / input_max
    ramp = np.minimum(rate * t, dm) if rate > 0 else np.full(t.size, dm)
    return np.array([sine, -sine, ramp, -ramp])


def simulate_corners(
    loop: ClosedLoop,
    box: UncertaintyBox,
    reference: Reference,
    disturbance: DisturbanceBound | None = None,
    noise_max: float = 0.0,
) -> BatchResult:
    """``loop`` simulated at every corner of ``box`` (its start: usually on the reference).

    Three reference periods (0.5 s at least), statistics over the last two; or, for a
    reference that settles (a step), until 1 s after it has settled with the statistics
    from its first move on, so that every move of the reference is simulated and
    measured, as the certificate covers every one. ``input_rate_max`` (over the same
    window) is what :func:`bwdesign.design.certified_envelope` compares with the
    envelope a robust certificate assumes. With a ``disturbance`` every corner runs
    each of :func:`disturbance_signals` (four scenarios per corner). With ``noise_max``
    every scenario has sensor noise at that bound (``noise_kind="bounded"``: ``+-noise_max``
    with a random sign at each sample, seeded by the scenario's index), as a certificate
    with ``|n| <= noise_max`` must face it: its input moves faster than without noise.
    """
    return simulate_plants(loop, box.vertices(loop.model), reference, disturbance, noise_max)


def span(reference: Reference) -> tuple[float, tuple[float, float] | None]:
    """The run length (s) and metrics window (``None``: the default) of
    :func:`simulate_corners` for ``reference``."""
    if reference.period is not None:
        return max(3 * reference.period, 0.5), None
    settles = max(reference.settles_at or 0.0, 0.0)
    duration = max(settles + 1.0, 1.0)
    moves = [float(b) for b in reference.breakpoints(0.0, settles)]
    return duration, ((min(moves, default=0.0), duration) if settles > 0 else None)


def simulate_plants(
    loop: ClosedLoop,
    plants: list,
    reference: Reference,
    disturbance: DisturbanceBound | None = None,
    noise_max: float = 0.0,
    pattern: Any = None,
) -> BatchResult:
    """:func:`simulate_corners` for any list of plants (duration, window, disturbance
    scenarios as there: ``len(plants) x`` the disturbance's signals, plant-major).

    ``pattern``: the noise of each plant (one row per plant, values in [-1, 1], times
    ``noise_max``: :data:`~bwdesign.sim.run.NOISE_KINDS`) instead of the random signs.
    """
    duration, window = span(reference)
    corners = list(plants)
    dist: Any = None
    k = 1
    if disturbance is not None and not disturbance.none:
        t = np.arange(int(round(duration / loop.dt))) * loop.dt
        sig = disturbance_signals(disturbance, t)
        k = len(sig)
        corners = [tp for tp in corners for _ in sig]
        dist = np.tile(sig, (len(corners) // k, 1))
    kind: Any = "bounded" if noise_max > 0 else "gaussian"  # none: nothing to label
    if pattern is not None:
        kind = np.repeat(np.atleast_2d(np.asarray(pattern, dtype=float)), k, axis=0)
    return simulate_batch(
        loop,
        reference,
        corners,
        duration=duration,
        window=window,
        input_disturbance=dist,
        noise_std=noise_max,
        seeds=np.arange(len(corners)),
        noise_kind=kind,
    )
