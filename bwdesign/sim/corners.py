"""The closed loop simulated at every corner of an uncertainty box (one batch)."""

from __future__ import annotations

from ..control.loop import ClosedLoop
from ..model.references import Reference
from ..model.uncertainty import UncertaintyBox
from .batch import BatchResult, simulate_batch

__all__ = ["simulate_corners"]


def simulate_corners(loop: ClosedLoop, box: UncertaintyBox, reference: Reference) -> BatchResult:
    """``loop`` simulated at every corner of ``box`` (its start: usually on the reference).

    Three reference periods (0.5 s at least), statistics over the last two; or, for a
    reference that settles (a step), until 1 s after it has settled with the statistics
    from its first move on, so that every move of the reference is simulated and
    measured, as the certificate covers every one. ``input_rate_max`` (over the same
    window) is what :func:`bwdesign.design.certified_envelope` compares with the
    envelope a robust certificate assumes.
    """
    if reference.period is not None:
        duration, window = max(3 * reference.period, 0.5), None
    else:
        settles = max(reference.settles_at or 0.0, 0.0)
        duration = max(settles + 1.0, 1.0)
        moves = [float(b) for b in reference.breakpoints(0.0, settles)]
        window = (min(moves, default=0.0), duration) if settles > 0 else None
    return simulate_batch(
        loop, reference, box.vertices(loop.model), duration=duration, window=window
    )
