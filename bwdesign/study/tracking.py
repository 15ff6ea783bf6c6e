"""The study's simulated tracking: the report's runs (with their commands) and the requirements'.

:func:`tracking_runs` simulates the tracking loop of a stage configuration the
way the report does (eq. 12 and the digital tuning, each with the PHSO, the
ESO and the disturbance observer PHDO, starting on the reference) and gives,
for every run, the
``bwdesign simulate`` command line that reproduces it exactly: the same
floats (``repr`` round-trips), the same initial state
(``--start-on-reference``), the input limits and the reference of the file.

The PHDO's four gains come from the 3-state gains of each law through the
package's one helper, :func:`bwdesign.observers.gains.disturbance_gains_from`
(``(l1, l2, 0, l3)``; for the digital tuning this is
``DigitalTuning.observer_gains_for("phdo")``).

:func:`corner_tracking` is what ``[requirements]`` max_me_um / max_maxe_um check: the
``[controller]`` law on the nominal plant and every ``[uncertainty]`` corner, simulated
together by :func:`bwdesign.simulate_batch`.
"""

from __future__ import annotations

import dataclasses
import math
import shlex
from dataclasses import dataclass
from itertools import product
from typing import Any

from ..control.loop import ON_REFERENCE, ClosedLoop, Start
from ..errors import InputError
from ..model.config import StageConfig
from ..model.envelope import Envelope, derive_envelope
from ..model.params import MODEL_FIELDS, BoucWenParams
from ..observers.spec import GAIN_KINDS
from ..sim.batch import BatchResult, simulate_batch
from ..sim.closed_loop import simulate
from ..sim.result import SimulationResult

__all__ = [
    "TrackingRun",
    "tracking_runs",
    "report_loops",
    "simulate_command",
    "corner_tracking",
    "true_plants",
    "input_limits",
    "required_input",
    "OBSERVERS",
]

#: The observers of the report's runs, in table order.
OBSERVERS = GAIN_KINDS


@dataclass(frozen=True)
class TrackingRun:
    """One simulated run of the report.

    Attributes
    ----------
    label : str
        ``"PHSO (eq. 12)"`` and the like.
    command : tuple of str
        Arguments of ``bwdesign`` that rerun it (``bwdesign.cli.main(list(command))``).
    result : SimulationResult
    """

    label: str
    command: tuple[str, ...]
    result: SimulationResult

    @property
    def command_text(self) -> str:
        """The command as a shell line."""
        return "bwdesign " + shlex.join(self.command)


def input_limits(config: StageConfig) -> tuple[float, float] | None:
    """``[controller] u_min, u_max`` (:meth:`ControllerSettings.input_limits`), or None."""
    return None if config.controller is None else config.controller.input_limits()


def required_input(
    config: StageConfig, env: Envelope, *, allow_unbounded: bool = False
) -> tuple[float, float] | None:
    """Range of the feedforward input the reference needs (exact inverse, last period).

    From the envelope when it was derived from the reference, else derived here;
    None when it cannot be (a sharp step has no finite-rate inverse).
    """
    if env.u_range is not None:
        return env.u_range
    try:
        derived = derive_envelope(config.plant, config.reference, allow_unbounded=allow_unbounded)
    except InputError:
        return None
    return derived.u_range


def _num(x: float) -> str:
    return repr(float(x))


def tracking_runs(
    config: StageConfig,
    *,
    gains: Any,
    tuning: Any,
    allow_unbounded: bool = False,
) -> tuple[TrackingRun, ...]:
    """The report's six runs: {eq. 12, digital tuning} x {PHSO, ESO, PHDO}.

    Parameters
    ----------
    config : StageConfig
        Needs [sampling], [reference] and [controller]; its ``source`` is the
        ``--plant`` of the commands.
    gains : array_like, shape (3,)
        Observer gains of the eq. 12 runs (1/s, 1/s^2, 1/s); the PHDO runs with
        ``disturbance_gains_from(gains)``.
    tuning : bwdesign.design.DigitalTuning
        The digital tuning's constants and gains (the PHDO's from
        ``tuning.observer_gains_for("phdo")``).
    allow_unbounded : bool

    Returns
    -------
    tuple of TrackingRun
        Each over three reference periods (1 s for a step), sampled at dt,
        nominal plant, no noise, limits ``[controller] u_min/u_max``, starting on
        the reference (``ClosedLoop(start="reference")``).
    """
    ref = config.reference
    duration = 3.0 * ref.period if ref.period is not None else 1.0
    runs = []
    for label, loop in report_loops(
        config, gains=gains, tuning=tuning, allow_unbounded=allow_unbounded
    ).items():
        r = simulate(loop, ref, duration=duration)
        runs.append(
            TrackingRun(
                label=label,
                command=tuple(simulate_command(config, loop, duration, allow_unbounded)),
                result=r,
            )
        )
    return tuple(runs)


def report_loops(
    config: StageConfig, *, gains: Any, tuning: Any, allow_unbounded: bool = False
) -> dict[str, ClosedLoop]:
    """The report's six loops by label (``"PHSO (eq. 12)"``, ...), in table order."""
    loops = {
        # the report's digital runs are simulated without the tuning's computation delay
        "eq. 12": lambda obs: ClosedLoop.from_config(
            config, observer=obs, gains=gains, allow_unbounded=allow_unbounded
        ),
        "digital tuning": lambda obs: ClosedLoop.from_config(
            config, observer=obs, law=tuning, allow_unbounded=allow_unbounded
        ).replace(delay=False),
    }
    return {
        f"{observer.upper()} ({law})": make(observer)
        for (law, make), observer in product(loops.items(), OBSERVERS)
    }


def simulate_command(
    config: StageConfig, loop: ClosedLoop, duration: float, unbounded: bool
) -> list:
    """The ``bwdesign simulate`` arguments that rerun ``loop`` (the reference from the file)."""
    ctrl, dt = loop.controller, loop.dt
    argv = ["simulate", "--plant", config.source, "--observer", loop.observer.kind]
    argv += ["--gains", ",".join(_num(g) for g in loop.observer.gains)]
    argv += ["--lambda1", _num(ctrl.lambda1), "--lambda2", _num(ctrl.lambda2)]
    discrete = getattr(ctrl, "dt", None) is not None
    argv += ["--form", "discrete" if discrete else "continuous"]
    if ctrl.integral_rate is not None:
        argv += ["--integral-rate", _num(ctrl.integral_rate)]
    argv += ["--dt", _num(dt), "--duration", _num(duration), "--start-on-reference"]
    limits = loop.input_limits
    if limits is not None and all(math.isfinite(v) for v in limits):
        argv += ["--u-min", _num(limits[0]), "--u-max", _num(limits[1])]
    # a one-sided limit and the reference come from the file's sections
    if unbounded:
        argv.append("--allow-unbounded")
    return argv


def true_plants(config: StageConfig, mismatch: Any = None) -> list[BoucWenParams]:
    """The plants the requirements' tracking runs on.

    With ``mismatch`` (relative errors, ``{"a1": 0.02}``) the one plant so perturbed;
    else the nominal plant and every corner of the ``[uncertainty]`` box (when the
    stage has one).
    """
    p = config.plant
    if mismatch is not None:
        bad = sorted(set(mismatch) - set(MODEL_FIELDS))
        if bad:
            raise InputError(f"mismatch: unknown parameter(s) {bad}; parameters: {MODEL_FIELDS}")
        changes = {k: getattr(p, k) * (1 + float(v)) for k, v in mismatch.items()}
        return [dataclasses.replace(p, **changes)]
    box = config.uncertainty
    if box is not None:
        return [p, *box.vertices(p)]
    return [p]


def corner_tracking(
    config: StageConfig,
    *,
    observer: str = "phso",
    noise_std: float = 0.0,
    duration: float | None = None,
    start: str = "reference",
    mismatch: Any = None,
    allow_unbounded: bool = False,
) -> tuple[float, int, BatchResult]:
    """The ``[controller]`` law tracking ``[reference]`` on :func:`true_plants`, as a batch.

    Eq. (12) with the ``[controller]`` constants (continuous form, its input limits),
    ``observer`` with the ``[observer]`` gains, at ``[sampling] dt``; ``duration``
    default three reference periods, at least 1 s; noise seeded with seed 1; starting
    on the reference (``start="reference"``) or from zero state and input (``"rest"``).

    Returns
    -------
    duration : float
    plants : int
        The number of plants simulated (the nominal plant first).
    result : BatchResult
    """
    period = config.reference.period
    duration = duration or max(1.0, 3 * period if period else 1.0)
    plants = true_plants(config, mismatch)
    if start not in ("reference", "rest"):
        raise InputError(f"start must be 'reference' or 'rest', got {start!r}")
    loop = ClosedLoop.from_config(
        config,
        observer=observer,
        start=ON_REFERENCE if start == "reference" else Start(),
        allow_unbounded=allow_unbounded,
    )
    res = simulate_batch(
        loop, config.reference, plants, duration=duration, noise_std=noise_std, seeds=1
    )
    return duration, len(plants), res
