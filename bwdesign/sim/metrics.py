"""Tracking metrics of the paper: MAXE, ME (mean ``|e|``) and RMSE over a window."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["Metrics", "tracking_metrics", "steady_state_window", "running_sum"]


@dataclass(frozen=True)
class Metrics:
    """Error statistics over ``window`` (plant length unit).

    Attributes
    ----------
    maxe : float
        ``max |e|``.
    me : float
        mean ``|e|`` (the paper's "mean error").
    rmse : float
        sqrt(mean e^2).
    window : tuple of float
        (t_start, t_end) in s, both inclusive.
    samples : int
        Number of samples in the window.
    """

    maxe: float
    me: float
    rmse: float
    window: tuple[float, float]
    samples: int

    def to_dict(self) -> dict:
        return {
            "maxe": self.maxe,
            "me": self.me,
            "rmse": self.rmse,
            "window": list(self.window),
            "samples": self.samples,
        }


def steady_state_window(
    t: np.ndarray, period: float | None, *, periods: float = 2.0, fraction: float = 0.5
) -> tuple[float, float]:
    """Default steady-state window: the last ``periods`` reference periods.

    For a non-periodic reference (``period`` is None) or a run shorter than
    ``periods`` periods, the last ``fraction`` of the run.
    """
    t = np.asarray(t, dtype=float)
    if t.size == 0:
        raise InputError("cannot choose a window on an empty time vector")
    t_end = float(t[-1])
    span = t_end - float(t[0])
    if period is not None and periods * period <= span:
        return (t_end - periods * period, t_end)
    return (t_end - fraction * span, t_end)


def running_sum(v: np.ndarray, axis: int = 0) -> Any:
    """The sum of ``v`` along ``axis`` added in order (``np.add.accumulate``), as the
    batched loop accumulates it; ``np.sum``'s pairwise order would differ in the last bits
    from :func:`bwdesign.sim.simulate_batch`'s metrics of the same run."""
    v = np.asarray(v, dtype=float)
    if v.shape[axis] == 0:
        return np.sum(v, axis=axis)
    return np.take(np.add.accumulate(v, axis=axis), -1, axis=axis)


def tracking_metrics(
    e: np.ndarray, t: np.ndarray | None = None, window: tuple[float, float] | None = None
) -> Metrics:
    """MAXE, ME and RMSE of the error ``e`` over ``window``.

    Parameters
    ----------
    e : array_like, shape (N,)
        Tracking (or estimation) error.
    t : array_like, shape (N,), optional
        Sample times (s). Without it, the whole of ``e`` is used.
    window : (float, float), optional
        (t_start, t_end) in s; defaults to the whole record.

    Raises
    ------
    InputError
        Shapes differ, the window holds no sample, or ``e`` is not finite.
    """
    e = np.asarray(e, dtype=float)
    if e.ndim != 1:
        raise InputError(f"e must be 1-D, got shape {e.shape}")
    if t is None:
        t = np.arange(e.size, dtype=float)
        if window is not None:
            raise InputError("a window needs the sample times t")
    t = np.asarray(t, dtype=float)
    if t.shape != e.shape:
        raise InputError(f"t and e must have the same shape, got {t.shape} and {e.shape}")
    if window is None:
        window = (float(t[0]), float(t[-1])) if t.size else (math.nan, math.nan)
    t0, t1 = window
    sel = (t >= t0 - 1e-12) & (t <= t1 + 1e-12)
    if not np.any(sel):
        raise InputError(f"window {window} holds no sample")
    w = e[sel]
    if not np.all(np.isfinite(w)):
        raise InputError("error signal is not finite in the window (did the loop diverge?)")
    a = np.abs(w)
    return Metrics(
        maxe=float(a.max()),
        me=float(running_sum(a) / w.size),
        rmse=float(np.sqrt(running_sum(w * w) / w.size)),
        window=(float(t0), float(t1)),
        samples=int(w.size),
    )
