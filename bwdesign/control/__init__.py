"""Tracking control: the eq. 12 controllers, the closed loop, loop systems and loop analysis, and
mismatch sweeps (the digital tuning, which chooses gains, is in :mod:`bwdesign.design`).
"""

from .analysis import LoopAnalysis, MismatchSweep, analyze_loop, mismatch_sweep, stability_interval
from .controllers import (
    ControlTerms,
    DiscreteTrackingController,
    TrackingController,
    TuningWarning,
    discrete_error_gains,
    discrete_integral_gains,
    eq12,
    error_feedback_gains,
    make_controller,
    solve_jump,
)
from .systems import closed_loop_matrix, loop_systems

__all__ = [
    "TrackingController",
    "DiscreteTrackingController",
    "ControlTerms",
    "TuningWarning",
    "eq12",
    "error_feedback_gains",
    "discrete_error_gains",
    "make_controller",
    "solve_jump",
    "discrete_integral_gains",
    "loop_systems",
    "closed_loop_matrix",
    "LoopAnalysis",
    "MismatchSweep",
    "analyze_loop",
    "mismatch_sweep",
    "stability_interval",
]
