"""A stage (either form) simulated on a record's input and scored against its output.

Used by ``bwdesign validate`` and by the structural identification's validation.
The piezo form follows its sample convention (docs/design.md, section "The sample
clock": ``u[k]`` held over ``[t_k, t_k + dt)``, ``y[k]`` at its end) and starts at
rest; the structural form takes point samples of a band-limited input
(:mod:`bwdesign.model.structural_sim`). ``periodic``: the record is one period of a
periodic input; the stage is simulated to its periodic steady state and that period
is scored.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import SolverError
from ..model.params import BoucWenParams
from ..model.plant import simulate_zoh
from ..model.structural import StructuralParams
from ..model.structural_sim import simulate_structural, steady_state
from .data import IdentificationData
from .result import fit_percent

__all__ = ["RecordScore", "score_record", "simulate_record", "SCORE_UPSAMPLE"]

#: Integration steps per sample when a structural stage is scored (error checked by doubling).
SCORE_UPSAMPLE = 8
#: Most periods simulated to reach the periodic steady state.
MAX_PERIODS = 50


@dataclass(frozen=True, eq=False)
class RecordScore:
    """The simulated output and its scores.

    Attributes
    ----------
    y_model : ndarray
        The stage's output at the record's samples.
    fit_percent : float
        ``100 (1 - ||y - y_model|| / ||y - mean(y)||)``.
    rms_error : float
        RMS of ``y - y_model`` (the record's output unit).
    integration_error : float or None
        Step-doubling estimate of the structural simulation's error (output unit).
    periods : int
        Periods simulated (1 unless periodic).
    """

    y_model: np.ndarray
    fit_percent: float
    rms_error: float
    integration_error: float | None
    periods: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "fit_percent": self.fit_percent,
            "rms_error": self.rms_error,
            "integration_error_estimate": self.integration_error,
            "periods_simulated": self.periods,
        }


def _piezo(
    plant: BoucWenParams, u: np.ndarray, dt: float, periodic: bool, allow_unbounded: bool
) -> tuple[np.ndarray, int]:
    x0, u_prev = np.zeros(3), 0.0
    x = simulate_zoh(plant, u, dt, x0, u_prev, allow_unbounded=allow_unbounded)
    if not periodic:
        return x[1:, 0], 1
    for period in range(2, MAX_PERIODS + 1):
        nxt = simulate_zoh(plant, u, dt, x[-1], u[-1], allow_unbounded=allow_unbounded)
        scale = np.maximum(np.max(np.abs(nxt), axis=0), 1e-300)
        if np.all(np.abs(nxt[-1] - x[-1]) <= 1e-10 * scale):
            return nxt[1:, 0], period
        x = nxt
    raise SolverError(f"no periodic steady state within {MAX_PERIODS} periods")


def simulate_record(
    plant: BoucWenParams | StructuralParams,
    data: IdentificationData,
    *,
    periodic: bool = False,
    allow_unbounded: bool = False,
) -> tuple[np.ndarray, float | None, int]:
    """The stage's output on ``data.u``: ``(y_model, integration error estimate, periods)``."""
    u, dt = np.asarray(data.u), data.dt
    if isinstance(plant, BoucWenParams):
        y, periods = _piezo(plant, u, dt, periodic, allow_unbounded)
        return y, None, periods
    opts: dict[str, Any] = {"upsample": SCORE_UPSAMPLE, "allow_unbounded": allow_unbounded}
    coarse, fine = {}, {"upsample": 2 * SCORE_UPSAMPLE}
    if plant.nu != 1.0:  # DOP853; the estimate compares two tolerances
        opts["method"] = "dop853"
        coarse, fine = {"rtol": 1e-9}, {"rtol": 1e-11}
    if periodic:
        run = steady_state(plant, u, dt, max_periods=MAX_PERIODS, **opts, **coarse)
        x0 = (run.y[0], run.v[0], run.z[0])
        periods = run.periods
    else:
        run = simulate_structural(plant, u, dt, **opts, **coarse)
        x0, periods = (0.0, 0.0, 0.0), 1
    opts.update(fine)
    finer = simulate_structural(plant, u, dt, periodic=periodic, x0=x0, **opts)
    scale = 15.0 if plant.nu == 1.0 else 1.0  # RK4: the doubling difference is 15 errors
    return finer.y, float(np.max(np.abs(finer.y - run.y))) / scale, periods


def score_record(
    plant: BoucWenParams | StructuralParams,
    data: IdentificationData,
    *,
    periodic: bool = False,
    allow_unbounded: bool = False,
) -> RecordScore:
    """Simulate ``plant`` on the record's input and score it against the record's output."""
    y_model, err, periods = simulate_record(
        plant, data, periodic=periodic, allow_unbounded=allow_unbounded
    )
    y = np.asarray(data.y)
    return RecordScore(
        y_model=y_model,
        fit_percent=fit_percent(y, y_model),
        rms_error=float(np.sqrt(np.mean((y - y_model) ** 2))),
        integration_error=err,
        periods=periods,
    )
