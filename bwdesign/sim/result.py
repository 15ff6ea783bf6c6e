"""The record of a closed-loop run."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .metrics import Metrics

__all__ = ["SimulationResult"]


STATE_NAMES = ("x1", "x2", "x3")


@dataclass(frozen=True)
class SimulationResult:
    """Record of a closed-loop run.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times (s).
    x : ndarray, shape (N, 3)
        True state at ``t`` (x1 length unit, x2 length unit/s, x3 length unit).
    xhat : ndarray, shape (N, 3)
        Estimate at ``t`` (the posterior, after the measurement at ``t``).
    u : ndarray, shape (N,)
        Input applied from ``t`` (V).
    x_d : ndarray, shape (N,)
        Reference (length unit).
    e : ndarray, shape (N,)
        Tracking error ``x1 - x_d`` (length unit).
    z : ndarray, shape (N,)
        Measured displacement (with noise); equal to x1 for the continuous path.
    metrics : Metrics or None
        MAXE, ME, RMSE of ``e`` over ``window``; None if the loop diverged.
    window : (float, float)
        Steady-state window (s): by default the last two reference periods.
    estimation_rmse : tuple of 3 floats or None
        RMS of ``xhat - x`` per state over the window.
    stable : bool
        False if the run diverged.
    status : str
        ``"ok"`` or what diverged and when.
    mode : str
        ``"sampled"`` or ``"continuous"``.
    settings : dict
        Everything needed to reproduce the run (JSON-safe).
    """

    t: np.ndarray
    x: np.ndarray
    xhat: np.ndarray
    u: np.ndarray
    x_d: np.ndarray
    e: np.ndarray
    z: np.ndarray
    metrics: Metrics | None
    window: tuple[float, float]
    estimation_rmse: tuple[float, float, float] | None
    stable: bool
    status: str
    mode: str
    settings: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("t", "x", "xhat", "u", "x_d", "e", "z"):
            arr = np.array(getattr(self, name), dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def length_unit(self) -> str:
        return self.settings.get("length_unit", "um")

    @property
    def input_unit(self) -> str:
        return self.settings.get("input_unit", "V")

    @property
    def saturated_fraction(self) -> float:
        """Fraction of samples at a ``u_limits`` bound (0 without limits)."""
        lim = self.settings.get("u_limits")
        if not lim or self.u.size == 0:
            return 0.0
        lo, hi = lim
        return float(np.mean((self.u <= lo) | (self.u >= hi)))

    def to_dict(self, *, series: bool = False) -> dict[str, Any]:
        """JSON-ready summary; ``series=True`` adds the time series."""
        lu = self.length_unit
        doc: dict[str, Any] = {
            "mode": self.mode,
            "stable": self.stable,
            "status": self.status,
            "length_unit": lu,
            "input_unit": self.input_unit,
            "metrics": None
            if self.metrics is None
            else {"maxe": self.metrics.maxe, "me": self.metrics.me, "rmse": self.metrics.rmse},
            "window": list(self.window),
            "window_samples": None if self.metrics is None else self.metrics.samples,
            "estimation_rmse": None
            if self.estimation_rmse is None
            else dict(zip(STATE_NAMES, self.estimation_rmse, strict=True)),
            "estimation_rmse_units": {"x1": lu, "x2": f"{lu}/s", "x3": lu},
            "u_range": [float(self.u.min()), float(self.u.max())] if self.u.size else None,
            "saturated_fraction": self.saturated_fraction,
            "samples": int(self.t.size),
            "settings": self.settings,
        }
        if series:
            doc["series"] = {
                "t": self.t.tolist(),
                "x": self.x.tolist(),
                "xhat": self.xhat.tolist(),
                "u": self.u.tolist(),
                "x_d": self.x_d.tolist(),
                "e": self.e.tolist(),
                "z": self.z.tolist(),
            }
        return doc

    def plot(self, **kwargs: Any) -> Any:
        """Plot the run (see :func:`bwdesign.plotting.plot_simulation`); returns (fig, axes)."""
        from ..plotting import figures as plotting

        return plotting.plot_simulation(self, **kwargs)
