"""The report's simulated tracking runs, each with the command that reproduces it.

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
"""

from __future__ import annotations

import math
import shlex
from dataclasses import dataclass
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

from ..control.loop import ClosedLoop
from ..errors import InputError
from ..model.config import StageConfig
from ..model.envelope import Envelope, derive_envelope
from ..sim.closed_loop import simulate
from ..sim.result import SimulationResult
from .document import fmt

__all__ = [
    "TrackingRun",
    "tracking_runs",
    "tracking_section",
    "input_limits",
    "limits_text",
    "required_input",
    "OBSERVERS",
]

#: Decades below each state's largest estimation error that the figure shows
#: (double-precision rounding of the states lies about 15 decades below them).
ESTIMATION_DECADES = 12

#: The observers of the report's runs, in table order.
OBSERVERS = ("phso", "eso", "phdo")


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
) -> list[TrackingRun]:
    """The report's six runs: {eq. 12, digital tuning} x {PHSO, ESO, PHDO}.

    Parameters
    ----------
    config : StageConfig
        Needs [sampling], [reference] and [controller]; its ``source`` is the
        ``--plant`` of the commands.
    gains : array_like, shape (3,)
        Observer gains of the eq. 12 runs (1/s, 1/s^2, 1/s); the PHDO runs with
        ``disturbance_gains_from(gains)``.
    tuning : bwdesign.control.DigitalTuning
        The digital tuning's constants and gains (the PHDO's from
        ``tuning.observer_gains_for("phdo")``).
    allow_unbounded : bool

    Returns
    -------
    list of TrackingRun
        Each over three reference periods (1 s for a step), sampled at dt,
        nominal plant, no noise, limits ``[controller] u_min/u_max``, starting on
        the reference (``ClosedLoop(start="reference")``).
    """
    ref = config.reference
    duration = 3.0 * ref.period if ref.period is not None else 1.0
    loops = {
        # the report's digital runs are simulated without the tuning's computation delay
        "eq. 12": lambda obs: ClosedLoop.from_config(
            config, observer=obs, gains=gains, allow_unbounded=allow_unbounded
        ),
        "digital tuning": lambda obs: ClosedLoop.from_config(
            config, observer=obs, law=tuning, allow_unbounded=allow_unbounded
        ).replace(delay=False),
    }
    runs = []
    for (law, make), observer in product(loops.items(), OBSERVERS):
        loop = make(observer)
        r = simulate(loop, ref, duration=duration)
        runs.append(
            TrackingRun(
                label=f"{observer.upper()} ({law})",
                command=tuple(_command(config, loop, duration, allow_unbounded)),
                result=r,
            )
        )
    return runs


def _command(config: StageConfig, loop: ClosedLoop, duration: float, unbounded: bool) -> list:
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


def limits_text(limits: Any, iu: str) -> str:
    """Input limits ``(lo, hi)`` as ``lo .. hi unit`` ("none" without limits)."""
    if limits is None:
        return "none"
    return f"{fmt(limits[0])} .. {fmt(limits[1])} {iu}"


def tracking_section(doc: Any, config: StageConfig, runs: list[TrackingRun], figs: Path) -> None:
    """Add the report's "Simulated tracking at the envelope" section for ``runs``.

    The table (one row per run, ``id="tracking"``), the commands that reproduce
    the runs, and the figures ``tracking.png`` and ``estimation_errors.png``
    written into ``figs``.
    """
    from ..plotting import figures as plotting

    params, ref, dt = config.plant, config.reference, float(config.dt)
    lu, iu = params.length_unit, params.input_unit
    doc.heading("Simulated tracking at the envelope")
    first = runs[0].result
    x0 = ", ".join(f"{x:.6g}" for x in first.settings["x0"])
    srow = []
    for run in runs:
        r = run.result
        sat = fmt(100 * r.saturated_fraction, 3) if r.settings.get("u_limits") else "no limits"
        if r.metrics is None:
            srow.append([run.label, "unstable", "-", "-", "-", "-", "-", sat])
            continue
        er = r.estimation_rmse
        srow.append(
            [
                run.label,
                fmt(r.metrics.maxe),
                fmt(r.metrics.me),
                fmt(r.metrics.rmse),
                fmt(er[0], 3),
                fmt(er[1], 3),
                fmt(er[2], 3),
                sat,
            ]
        )
    w = first.window
    doc.para(
        f"Reference {ref.describe()}, dt = {dt * 1e3:g} ms, {first.settings['duration']:g} s "
        f"starting on the reference: plant state and estimate x0 = ({x0}) "
        f"({lu}, {lu}/s, {lu}), i.e. (x_d(0), x_d'(0), 0), with the feedforward input "
        f"{first.settings['u_prev']:.6g} {iu} held before t = 0; nominal plant, no noise; "
        f"input limits {limits_text(input_limits(config), iu)}. Metrics over the last "
        f"two periods ({w[0]:g} .. {w[1]:g} s), in {lu}; estimation RMSE per state; "
        "saturated = share of samples at an input limit."
    )
    phdo = [run for run in runs if run.command[run.command.index("--observer") + 1] == "phdo"]
    if phdo:
        doc.para(
            "PHDO = the hysteresis observer with a disturbance state "
            "(bwdesign.DisturbanceHysteresisObserver, states x1, x2, x3, d). Its four gains "
            "are (l1, l2, 0, l3) from the 3-state gains of the same law, through the package's "
            "one helper bwdesign.observers.gains.disturbance_gains_from: "
            + "; ".join(f"{run.label}: {_gains_cell(run.command)}" for run in phdo)
            + ". Its x3 column is the lumped estimate x3hat + d against x3 (what the law "
            "uses); on the nominal plant without noise d stays 0 and it runs as the PHSO."
        )
    doc.table(
        [
            "loop",
            f"MAXE ({lu})",
            f"ME ({lu})",
            f"RMSE ({lu})",
            "RMSE x1",
            "RMSE x2",
            "RMSE x3",
            "saturated (%)",
        ],
        srow,
        id="tracking",
    )
    doc.para(
        "Each run is reproduced exactly by the command below it (`--start-on-reference` sets "
        "the initial state above; the reference and any one-sided input limit come from the "
        "config file's sections; the path is as given to `bwdesign report`):"
    )
    doc.pre("\n".join(f"# {run.label}\n{run.command_text}" for run in runs))
    runs_by_label = {run.label: run.result for run in runs}
    fig, _ = plotting.plot_tracking_comparison(runs_by_label, title="tracking at the envelope")
    plotting.save_figure(fig, figs / "tracking.png")
    doc.figure("figures/tracking.png", "Tracking, error and input over the metrics window")
    curves = {}
    panels = {
        "x1 displacement": f"|x1hat - x1| ({lu})",
        "x2 velocity": f"|x2hat - x2| ({lu}/s)",
        "x3 hysteresis": f"|x3hat - x3| ({lu})",
    }
    for label, r in runs_by_label.items():
        if r.stable:
            err = np.asarray(r.xhat) - np.asarray(r.x)
            for i, panel in enumerate(panels):
                curves[f"{panel} | {label}"] = (np.asarray(r.t), err[:, i])
    if curves:
        fig, _ = plotting.plot_estimation_errors(
            curves,
            title="estimation errors in the loop",
            ylabel=panels,
            stack=True,
            decades=ESTIMATION_DECADES,
        )
        plotting.save_figure(fig, figs / "estimation_errors.png")
        doc.figure("figures/estimation_errors.png", "Estimation error of each state in the loop")
    else:
        doc.para("No run stayed bounded, so there is no estimation-error figure.")


def _gains_cell(command: tuple[str, ...]) -> str:
    """The ``--gains`` of a run's command as ``(g1, g2, ...)`` (6 significant digits)."""
    gains = command[command.index("--gains") + 1].split(",")
    return "(" + ", ".join(f"{float(g):.6g}" for g in gains) + ")"
