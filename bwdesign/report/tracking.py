"""The report's "Simulated tracking at the envelope" section, rendered from :attr:`Study.tracking`.

The runs and their reproducing commands are computed by :mod:`bwdesign.study.tracking`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..output.text import limits_text
from ..study import Study
from ..study.tracking import input_limits
from .document import Document, fmt
from .figures import FigureWriter, as_writer

__all__ = ["tracking_section", "ESTIMATION_DECADES"]

#: Decades below each state's largest estimation error that the figure shows
#: (double-precision rounding of the states lies about 15 decades below them).
ESTIMATION_DECADES = 12


def tracking_section(doc: Document, study: Study, figs: FigureWriter | Path) -> None:
    """Add the report's "Simulated tracking at the envelope" section for the study's runs.

    The table (one row per run, ``id="tracking"``), the commands that reproduce
    the runs, and the figures ``tracking.png`` and ``estimation_errors.png``
    written into ``figs`` (a folder, or a :class:`~bwdesign.report.figures.FigureWriter`).
    """
    from ..plotting import figures as plotting

    figs = as_writer(figs)

    config, runs = study.config, study.tracking
    params, ref, dt = config.plant, config.reference, float(config.dt)
    lu, iu = params.length_unit, params.input_unit
    doc.heading("Simulated tracking at the envelope")
    first = runs[0].result
    x0 = ", ".join(f"{x:.6g}" for x in first.settings["x0"])
    srow = [_row(run) for run in runs]
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
    figs.save(
        "tracking.png",
        lambda: plotting.plot_tracking_comparison(runs_by_label, title="tracking at the envelope")[
            0
        ],
    )
    doc.figure(f"{figs.name}/tracking.png", "Tracking, error and input over the metrics window")
    _estimation_figure(doc, runs_by_label, figs, lu, plotting)


def _row(run: Any) -> list[str]:
    """A run's row: MAXE, ME, RMSE, estimation RMSE per state, saturated share."""
    r = run.result
    sat = fmt(100 * r.saturated_fraction, 3) if r.settings.get("u_limits") else "no limits"
    if r.metrics is None:
        return [run.label, "unstable", "-", "-", "-", "-", "-", sat]
    er = r.estimation_rmse
    m = r.metrics
    return [run.label, fmt(m.maxe), fmt(m.me), fmt(m.rmse)] + [fmt(e, 3) for e in er[:3]] + [sat]


def _estimation_figure(
    doc: Document, results: dict[str, Any], figs: FigureWriter, lu: str, plotting: Any
) -> None:
    """The estimation error of each state of every bounded run (or a sentence: none)."""
    curves = {}
    panels = {
        "x1 displacement": f"|x1hat - x1| ({lu})",
        "x2 velocity": f"|x2hat - x2| ({lu}/s)",
        "x3 hysteresis": f"|x3hat - x3| ({lu})",
    }
    for label, r in results.items():
        if r.stable:
            err = np.asarray(r.xhat) - np.asarray(r.x)
            for i, panel in enumerate(panels):
                curves[f"{panel} | {label}"] = (np.asarray(r.t), err[:, i])
    if not curves:
        doc.para("No run stayed bounded, so there is no estimation-error figure.")
        return
    figs.save(
        "estimation_errors.png",
        lambda: plotting.plot_estimation_errors(
            curves,
            title="estimation errors in the loop",
            ylabel=panels,
            stack=True,
            decades=ESTIMATION_DECADES,
        )[0],
    )
    doc.figure(f"{figs.name}/estimation_errors.png", "Estimation error of each state in the loop")


def _gains_cell(command: tuple[str, ...]) -> str:
    """The ``--gains`` of a run's command as ``(g1, g2, ...)`` (6 significant digits)."""
    gains = command[command.index("--gains") + 1].split(",")
    return "(" + ", ".join(f"{float(g):.6g}" for g in gains) + ")"
