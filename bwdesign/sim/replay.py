"""Replay one row of a sweep with :func:`simulate`, and say how far the row reproduces.

A sweep's rows come from :func:`bwdesign.sim.batch.simulate_batch`, which does the
scalar loop's operations in the same order, so a replay agrees with its row to
rounding -- where the loop is insensitive to rounding. Where it is sensitive (a
chattering loop, typically with its input far outside the envelope its
certificate assumed), rounding differences grow to percent within a run: the row
is reproduced bit for bit by the same sweep (same seed, any chunking, same
machine and libraries), but a replay with :func:`simulate`, another machine, or
a parameter changed in its last digit agree with it only statistically.

:func:`replay_row` replays a row, replays it once more with ``a1`` changed by
:data:`SENSITIVITY_STEP` (relative), and states both differences; a row whose
replay or probe moves ME or MAXE by more than :data:`SENSITIVE_RTOL` (relative)
is marked ``sensitive``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import MODEL_FIELDS
from .closed_loop import simulate
from .result import SimulationResult
from .sweep import SweepSpec

__all__ = ["RowReplay", "replay_row", "SENSITIVITY_STEP", "SENSITIVE_RTOL"]

#: Relative change of ``a1`` with which :func:`replay_row` probes a row's sensitivity.
SENSITIVITY_STEP = 1e-12
#: A replay or probe moving ME or MAXE by more than this (relative) marks a row sensitive:
#: an insensitive loop amplifies the probe's 1e-12 at most ~1e3-fold (measured on the
#: bundled stages), a chaotic one to 1e-5 .. 1e-2.
SENSITIVE_RTOL = 1e-6
_KEYS = ("me", "maxe", "input_rate_max")


@dataclass(frozen=True)
class RowReplay:
    """A sweep row beside its replay with :func:`simulate` and a perturbed replay.

    Attributes
    ----------
    scenario : int
    observer : str
    row, replayed, perturbed : dict or None
        ``me``, ``maxe`` (length unit) and ``input_rate_max`` (input unit/s) of the
        row, of its replay, and of the replay with ``a1 * (1 + SENSITIVITY_STEP)``;
        None where that run diverged.
    replay_difference : float or None
        Largest relative difference of ME and MAXE between replay and row
        (``inf`` when one diverged and the other did not; None when both diverged).
    perturbation_change : float or None
        The same between the perturbed replay and the replay.
    sensitive : bool or None
        Either difference above :data:`SENSITIVE_RTOL` (None when every run diverged).
    run : SimulationResult
        The replay's full record.
    """

    scenario: int
    observer: str
    row: dict[str, float] | None
    replayed: dict[str, float] | None
    perturbed: dict[str, float] | None
    replay_difference: float | None
    perturbation_change: float | None
    sensitive: bool | None
    run: SimulationResult = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (the record ``run`` left out)."""
        return {
            "scenario": self.scenario,
            "observer": self.observer,
            "row": self.row,
            "replayed": self.replayed,
            "perturbed": self.perturbed,
            "sensitivity_step": SENSITIVITY_STEP,
            "replay_difference": self.replay_difference,
            "perturbation_change": self.perturbation_change,
            "sensitive": self.sensitive,
        }


def _run_metrics(run: SimulationResult, dt: float) -> dict[str, float] | None:
    if not run.stable or run.metrics is None:
        return None
    t = np.asarray(run.t)
    sel = (t >= run.window[0] - 1e-12) & (t <= run.window[1] + 1e-12)
    rate = np.abs(np.diff(np.asarray(run.u)))[sel[1:]] / dt
    return {
        "me": float(run.metrics.me),
        "maxe": float(run.metrics.maxe),
        "input_rate_max": float(rate.max()) if rate.size else math.nan,
    }


def _difference(a: dict[str, float] | None, b: dict[str, float] | None) -> float | None:
    if a is None and b is None:
        return None
    if a is None or b is None:
        return math.inf
    return max(abs(a[k] - b[k]) / abs(b[k]) if b[k] else abs(a[k]) for k in ("me", "maxe"))


def replay_row(
    spec: SweepSpec,
    table: Mapping[str, np.ndarray],
    scenario: int,
    observer: str,
) -> RowReplay:
    """Replay ``scenario``'s ``observer`` row of a sweep ``table`` (from ``spec``).

    Raises
    ------
    InputError
        No such row in ``table``.
    """
    hit = np.flatnonzero((table["scenario"] == scenario) & (table["observer"] == observer))
    if hit.size != 1:
        raise InputError(f"the table holds no row for scenario {scenario}, observer {observer!r}")
    i = int(hit[0])
    tp = replace(spec.params, **{k: float(table[k][i]) for k in MODEL_FIELDS})
    loop = spec.loop_for(observer)

    def run(true_params):
        return simulate(
            loop,
            spec.reference,
            duration=spec.duration,
            true_params=true_params,
            noise_std=spec.noise_std,
            seed=int(table["noise_seed"][i]),
        )

    replayed = run(tp)
    perturbed = run(replace(tp, a1=tp.a1 * (1 + SENSITIVITY_STEP)))
    row = {k: float(table[k][i]) for k in _KEYS if k in table} if bool(table["stable"][i]) else None
    got, probe = _run_metrics(replayed, spec.dt), _run_metrics(perturbed, spec.dt)
    d_replay, d_probe = _difference(got, row), _difference(probe, got)
    known = [d for d in (d_replay, d_probe) if d is not None]
    return RowReplay(
        scenario=int(scenario),
        observer=observer,
        row=row,
        replayed=got,
        perturbed=probe,
        replay_difference=d_replay,
        perturbation_change=d_probe,
        sensitive=any(d > SENSITIVE_RTOL for d in known) if known else None,
        run=replayed,
    )
