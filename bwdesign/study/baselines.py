"""The study's baselines: what a user would keep, beside the observer-based loops.

:func:`baseline_comparison` (the part ``baselines``) simulates the four baseline
controllers of :mod:`bwdesign.control.baselines` (PI, PID, PI with the inverse
Bouc–Wen feedforward, PI with the Prandtl–Ishlinskii compensator; each tuned by the
phase-margin rule of :func:`bwdesign.control.baseline_tuning.tune_baseline` at 60 deg,
with the ``[controller]`` input limits) beside the report's six observer-based loops
(:func:`bwdesign.study.tracking.report_loops`) on the stage's reference: on the nominal
plant, and at the worst corner (largest ME, per loop) of the ``[uncertainty]`` box, or
of :data:`DEFAULT_BOX` (+-2 % on the linear part, +-10 % on the hysteresis) when the
stage has none. The runs are as the report's tracking runs: three reference periods,
starting on the reference, no noise, no computation delay, metrics over the last two
periods. The nominal plant and the corners are simulated as one batch
(:func:`bwdesign.simulate_batch`, which also counts the saturated samples; a loop the
report's tracking runs already simulated keeps that nominal run), and every row
carries the ``bwdesign simulate`` command that reproduces it (a corner by ``--mismatch``,
:func:`bwdesign.model.mismatch.corner_text`).

:func:`configured_baseline` (the part ``baseline``) is the ``[baseline]`` controller's
nominal linear analysis, which the requirement ``baseline_stable`` checks.
"""

from __future__ import annotations

import math
import shlex
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..control.baseline_tuning import BaselineAnalysis, analyze_baseline
from ..control.loop import ClosedLoop
from ..errors import BWDesignError
from ..model.config import BASELINE_KINDS, StageConfig
from ..model.mismatch import corner_text
from ..model.references import Reference, Sine, Step, Triangle
from ..model.uncertainty import UncertaintyBox
from ..sim.batch import BatchResult, simulate_batch
from ..sim.result import SimulationResult
from .tracking import TrackingRun, report_loops, simulate_command

__all__ = [
    "LoopOutcome",
    "ComparisonRow",
    "Winner",
    "BaselineComparison",
    "ConfiguredBaseline",
    "baseline_comparison",
    "configured_baseline",
    "DEFAULT_BOX",
    "BASELINE_LABELS",
]

#: The box of the worst-corner rows for a stage without ``[uncertainty]``: a model error
#: of the size an identification leaves (+-2 % linear, +-10 % hysteresis).
DEFAULT_BOX = UncertaintyBox.from_dict(
    {
        **{k: {"rel": 0.02} for k in ("a1", "a2", "a3")},
        **{k: {"rel": 0.1} for k in ("alpha", "beta", "gamma")},
    }
)
#: Row labels of the baselines, by kind.
BASELINE_LABELS = {
    "pi": "PI",
    "pid": "PID",
    "pi-bwff": "PI + inverse Bouc-Wen",
    "pi-piff": "PI + Prandtl-Ishlinskii",
}


@dataclass(frozen=True)
class LoopOutcome:
    """One simulated run of a row: its metrics (length unit) and the command.

    ``saturated`` is the share of samples at an input limit (None without limits);
    ``corner`` the ``--mismatch`` text of the plant (None: nominal).
    """

    stable: bool
    status: str
    me: float | None
    maxe: float | None
    rmse: float | None
    saturated: float | None
    command: tuple[str, ...]
    corner: str | None = None

    @property
    def command_text(self) -> str:
        return "bwdesign " + shlex.join(self.command)

    def to_dict(self) -> dict[str, Any]:
        return {**self.__dict__, "command": self.command_text}


@dataclass(frozen=True)
class ComparisonRow:
    """A loop: ``baseline`` (no observer) or observer-based, nominal and worst corner."""

    label: str
    baseline: bool
    nominal: LoopOutcome
    worst: LoopOutcome

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "baseline": self.baseline,
            "nominal": self.nominal.to_dict(),
            "worst_corner": self.worst.to_dict(),
        }


@dataclass(frozen=True)
class Winner:
    """The loop with the smallest ME, and the best of the other kind (baseline or not).

    ``factor`` = the other's ME over the winner's (inf when the other has no stable run).
    """

    label: str
    baseline: bool
    me: float
    other: str | None
    other_me: float | None
    factor: float

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class BaselineComparison:
    """The part ``baselines`` (module docstring)."""

    reference: Reference
    box: UncertaintyBox
    box_source: str
    corners: int
    duration: float
    window: tuple[float, float]
    rows: tuple[ComparisonRow, ...]
    nominal_winner: Winner | None
    worst_winner: Winner | None

    def to_dict(self) -> dict[str, Any]:
        return {
            "reference": self.reference.to_dict(),
            "box": self.box.widths,
            "box_source": self.box_source,
            "corners": self.corners,
            "duration": self.duration,
            "window": list(self.window),
            "rows": [r.to_dict() for r in self.rows],
            "nominal_winner": None
            if self.nominal_winner is None
            else self.nominal_winner.to_dict(),
            "worst_winner": None if self.worst_winner is None else self.worst_winner.to_dict(),
        }


def _dict(value: Any) -> Any:
    return None if value is None else value.to_dict()


@dataclass(frozen=True)
class ConfiguredBaseline:
    """The ``[baseline]`` controller (its ``to_dict``) and its nominal linear analysis."""

    kind: str
    controller: dict[str, Any]
    analysis: BaselineAnalysis

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "controller": self.controller,
            "analysis": self.analysis.to_dict(),
        }


def configured_baseline(config: StageConfig, *, allow_unbounded: bool = False) -> Any:
    """The ``[baseline]`` controller's nominal analysis (None without the section)."""
    spec = config.baseline
    if spec is None:
        return None
    loop = ClosedLoop.baseline_from_config(
        config,
        spec["kind"],
        gains=spec["gains"],
        phase_margin=spec["phase_margin"],
        delay=spec["delay"],
        allow_unbounded=allow_unbounded,
    )
    return ConfiguredBaseline(
        kind=spec["kind"],
        controller=loop.controller.to_dict(),
        analysis=analyze_baseline(loop.controller, config.plant, delay=spec["delay"]),
    )


def reference_options(ref: Reference) -> list[str]:
    """``bwdesign simulate`` options giving ``ref`` (empty when the file must give it)."""
    d = ref.to_dict()
    if isinstance(ref, Sine | Triangle) and not d.get("corner_time"):
        keys = ("amplitude", "offset", "frequency", "phase")
    elif isinstance(ref, Step):
        keys = ("amplitude", "offset", "t_step", "rise_time")
    else:
        return []
    out = ["--reference", d["kind"]]
    for k in keys:
        out += [f"--{k.replace('_', '-')}", repr(float(d[k]))]
    return out


def _outcome(r: SimulationResult, command: list[str], corner: str | None) -> LoopOutcome:
    m = r.metrics
    sat = r.saturated_fraction if r.settings.get("u_limits") else None
    return LoopOutcome(
        stable=bool(r.stable and m is not None),
        status=r.status,
        me=None if m is None else m.me,
        maxe=None if m is None else m.maxe,
        rmse=None if m is None else m.rmse,
        saturated=sat,
        command=tuple(command),
        corner=corner,
    )


def _baseline_command(config, kind, duration, limits, unbounded) -> list[str]:
    argv = ["simulate", "--plant", config.source, "--controller", kind]
    argv += ["--duration", repr(float(duration)), "--start-on-reference"]
    if limits is not None and all(math.isfinite(v) for v in limits):
        argv += ["--u-min", repr(limits[0]), "--u-max", repr(limits[1])]
    return argv + (["--allow-unbounded"] if unbounded else [])


def _batch_outcome(b: BatchResult, i: int, command: list[str], corner: str | None):
    """Scenario ``i`` of a batch as a row's run (its saturated share from the batch)."""
    ok = bool(b.stable[i])
    return LoopOutcome(
        stable=ok,
        status=b.status[i],
        me=float(b.me[i]) if ok else None,
        maxe=float(b.maxe[i]) if ok else None,
        rmse=float(b.rmse[i]) if ok else None,
        saturated=float(b.saturated_fraction[i]) if b.settings["controller"].get("u_limits")
        else None,
        command=tuple(command),
        corner=corner,
    )  # fmt: skip


def _runs(loop, ref, duration, plants, command, box, params) -> tuple[Any, Any, tuple]:
    """The nominal run, the corner with the largest ME (an unstable one first) and the
    metrics window, from one batch of the nominal plant and the corners."""
    b = simulate_batch(loop, ref, [params, *plants], duration=duration)
    me = np.where(b.stable[1:], b.me[1:], np.inf)
    i = int(np.argmax(me)) + 1
    text = corner_text(box, params, plants[i - 1])
    nominal = _batch_outcome(b, 0, command, None)
    return nominal, _batch_outcome(b, i, [*command, "--mismatch", text], text), b.window


def _winner(rows: list[ComparisonRow], where: str) -> Winner | None:
    def me(row):
        o = getattr(row, where)
        return o.me if o.stable and o.me is not None else math.inf

    ranked = sorted(rows, key=me)
    if not ranked or not math.isfinite(me(ranked[0])):
        return None
    best = ranked[0]
    other = next((r for r in ranked if r.baseline != best.baseline), None)
    other_me = None if other is None else me(other)
    factor = math.inf if other_me is None or not math.isfinite(other_me) else other_me / me(best)
    return Winner(
        label=best.label,
        baseline=best.baseline,
        me=me(best),
        other=None if other is None else other.label,
        other_me=other_me if other_me is not None and math.isfinite(other_me) else None,
        factor=factor,
    )


def baseline_comparison(
    config: StageConfig,
    *,
    gains: Any,
    tuning: Any,
    tracking: tuple[TrackingRun, ...] | None = None,
    reference: Reference | None = None,
    allow_unbounded: bool = False,
) -> BaselineComparison:
    """The part ``baselines`` (module docstring).

    Parameters
    ----------
    config : StageConfig
        Needs ``[sampling]``, ``[reference]``, ``[controller]``.
    gains, tuning
        The observer loops' gains and digital tuning (as :func:`tracking_runs`).
    tracking : tuple of TrackingRun, optional
        The report's tracking runs: their nominal results are reused (same loops).
    reference : Reference, optional
        Another reference than ``[reference]`` (its options are then in the commands).
    """
    ref = config.reference if reference is None else reference
    extra = [] if reference is None else reference_options(reference)
    duration = 3.0 * ref.period if ref.period is not None else 1.0
    box = config.uncertainty or DEFAULT_BOX
    source = "[uncertainty]" if config.uncertainty is not None else "default"
    params = config.plant
    plants = box.vertices(params)
    known = {} if tracking is None or reference is not None else {t.label: t for t in tracking}
    limits = None if config.controller is None else config.controller.input_limits()
    rows: list[ComparisonRow] = []
    window = None
    for kind in BASELINE_KINDS:
        cmd = _baseline_command(config, kind, duration, limits, allow_unbounded) + extra
        try:
            loop = ClosedLoop.baseline_from_config(config, kind, allow_unbounded=allow_unbounded)
            nominal, worst, window = _runs(loop, ref, duration, plants, cmd, box, params)
        except BWDesignError as err:  # e.g. no exact inverse outside the bounded class
            gone = LoopOutcome(False, f"not run: {err}", None, None, None, None, tuple(cmd))
            rows.append(ComparisonRow(BASELINE_LABELS[kind], True, gone, gone))
            continue
        rows.append(ComparisonRow(BASELINE_LABELS[kind], True, nominal, worst))
    observer_loops = report_loops(
        config, gains=gains, tuning=tuning, allow_unbounded=allow_unbounded
    )
    for label, loop in observer_loops.items():
        cmd = simulate_command(config, loop, duration, allow_unbounded) + extra
        nominal, worst, window = _runs(loop, ref, duration, plants, cmd, box, params)
        if label in known:  # the report's own tracking run of this loop
            nominal = _outcome(known[label].result, cmd, None)
        rows.append(ComparisonRow(label, False, nominal, worst))
    return BaselineComparison(
        reference=ref,
        box=box,
        box_source=source,
        corners=len(plants),
        duration=duration,
        window=tuple(float(w) for w in window),
        rows=tuple(rows),
        nominal_winner=_winner(rows, "nominal"),
        worst_winner=_winner(rows, "worst"),
    )
