"""The report's simulated tracking runs, each with the command that reproduces it.

:func:`tracking_runs` simulates the tracking loop of a stage configuration the
way the report does (eq. 12 and the digital tuning, each with the PHSO and the
ESO, starting on the reference) and gives, for every run, the
``bwdesign simulate`` command line that reproduces it exactly: the same
floats (``repr`` round-trips), the same initial state
(``--start-on-reference``), the input limits and the reference of the file.
"""

from __future__ import annotations

import math
import shlex
from dataclasses import dataclass
from itertools import product
from typing import Any

from ..errors import InputError
from ..model.config import StageConfig
from ..model.envelope import Envelope, derive_envelope
from ..sim.closed_loop import simulate
from ..sim.result import SimulationResult
from ..sim.start import start_on_reference

__all__ = ["TrackingRun", "tracking_runs", "input_limits", "required_input"]


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
    """``[controller] u_min, u_max`` as a (lo, hi) pair (input unit; inf for a missing side)."""
    ctl = config.controller
    if ctl is None or (ctl.u_min is None and ctl.u_max is None):
        return None
    return (
        -math.inf if ctl.u_min is None else ctl.u_min,
        math.inf if ctl.u_max is None else ctl.u_max,
    )


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
) -> list[TrackingRun]:
    """The report's four runs: {eq. 12, digital tuning} x {PHSO, ESO}.

    Parameters
    ----------
    config : StageConfig
        Needs [sampling], [reference] and [controller]; its ``source`` is the
        ``--plant`` of the commands.
    gains : array_like, shape (3,)
        Observer gains of the eq. 12 runs (1/s, 1/s^2, 1/s).
    tuning : bwdesign.control.DigitalTuning
        The digital tuning's constants and gains.
    allow_unbounded : bool

    Returns
    -------
    list of TrackingRun
        Each over three reference periods (1 s for a step), sampled at dt,
        nominal plant, no noise, limits ``[controller] u_min/u_max``, starting on
        the reference (:func:`bwdesign.sim.start_on_reference`).
    """
    params, ref, ctl, dt = config.plant, config.reference, config.controller, float(config.dt)
    duration = 3.0 * ref.period if ref.period is not None else 1.0
    start = start_on_reference(params, ref)
    limits = input_limits(config)
    laws = {
        "eq. 12": dict(
            gains=tuple(float(g) for g in gains),
            lambda1=ctl.lambda1,
            lambda2=ctl.lambda2,
            form="continuous",
            integral_rate=None,
        ),
        "digital tuning": dict(
            gains=tuple(float(g) for g in tuning.gains),
            lambda1=float(tuning.lambda1),
            lambda2=float(tuning.lambda2),
            form="discrete",
            integral_rate=None if tuning.integral_rate is None else float(tuning.integral_rate),
        ),
    }
    runs = []
    for (law, kw), observer in product(laws.items(), ("phso", "eso")):
        r = simulate(
            params,
            ref,
            dt=dt,
            duration=duration,
            observer=observer,
            u_limits=limits,
            allow_unbounded=allow_unbounded,
            **start,
            **kw,
        )
        argv = ["simulate", "--plant", config.source, "--observer", observer]
        argv += ["--gains", ",".join(_num(g) for g in kw["gains"])]
        argv += ["--lambda1", _num(kw["lambda1"]), "--lambda2", _num(kw["lambda2"])]
        argv += ["--form", kw["form"]]
        if kw["integral_rate"] is not None:
            argv += ["--integral-rate", _num(kw["integral_rate"])]
        argv += ["--dt", _num(dt), "--duration", _num(duration), "--start-on-reference"]
        if limits is not None and all(math.isfinite(v) for v in limits):
            argv += ["--u-min", _num(limits[0]), "--u-max", _num(limits[1])]
        # a one-sided limit and the reference come from the file's sections
        if allow_unbounded:
            argv.append("--allow-unbounded")
        runs.append(TrackingRun(label=f"{observer.upper()} ({law})", command=tuple(argv), result=r))
    return runs
