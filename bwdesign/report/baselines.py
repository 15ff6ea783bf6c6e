"""The report's "Baselines" section, rendered from :attr:`Study.baselines`.

The runs, their metrics, the worst corners, the winners and the reproducing commands
are computed by :mod:`bwdesign.study.baselines`; nothing is computed here.
"""

from __future__ import annotations

import math
from typing import Any

from ..study import Study
from ..study.baselines import BaselineComparison, LoopOutcome, Winner
from .document import Document, fmt

__all__ = ["baselines_section", "winner_sentence"]


def _cells(o: LoopOutcome) -> list[str]:
    sat = "no limits" if o.saturated is None else fmt(100 * o.saturated, 3)
    if o.status.startswith("not run"):
        return ["not run", "-", "-", "-"]
    if not o.stable:
        return ["unstable", "-", "-", sat]
    return [fmt(o.me), fmt(o.maxe), fmt(o.rmse), sat]


def winner_sentence(w: Winner | None, where: str, lu: str) -> str:
    """One sentence: which loop wins ``where`` and by how much (from the study's numbers)."""
    if w is None:
        return f"{where}: no loop stays bounded."
    kind = "a baseline" if w.baseline else "an observer-based loop"
    head = f"{where}: {kind}, {w.label}, wins with ME {fmt(w.me)} {lu}"
    if w.other is None:
        return head + "."
    other = "baseline" if not w.baseline else "observer-based loop"
    if w.other_me is None or math.isinf(w.factor):
        return head + f"; no {other} stays bounded."
    best = f"{w.other} ({fmt(w.other_me)} {lu})"
    return head + f", {fmt(w.factor, 3)} times lower than the best {other}, {best}."


def _box_text(b: BaselineComparison, params: Any) -> str:
    if b.box_source == "[uncertainty]":
        return f"the stage's [uncertainty] box ({b.box.describe(params)})"
    return (
        "a default box of +-2 % on a1, a2, a3 and +-10 % on alpha, beta, gamma (the stage has "
        f"no [uncertainty]; the size of model error an identification leaves): "
        f"{b.box.describe(params)}"
    )


def baselines_section(doc: Document, study: Study) -> None:
    """Add the section: the table (``id="baselines"``), the winner sentences, the commands."""
    b: BaselineComparison = study.baselines
    params = study.config.plant
    lu = params.length_unit
    doc.heading("Baselines: the loops a user would keep instead")
    rule = next((r for r in b.rows if r.baseline), None)
    doc.para(
        "PI, PID (filtered derivative on the measurement), PI with the exact inverse "
        "Bouc-Wen model as feedforward and PI with a Prandtl-Ishlinskii compensator (10 play "
        "operators fitted to the model's quasi-static loops, analytic inverse): no observer, "
        "anti-windup by conditional integration on the input limits, each tuned by the "
        "phase-margin rule (60 deg at the crossover of the sampled nominal linear model; "
        "bwdesign.control.baseline_tuning), beside the observer-based loops of the tracking "
        f"section, on the reference {b.reference.describe()}: {b.duration:g} s from the "
        f"reference, no noise, metrics over {b.window[0]:g} .. {b.window[1]:g} s in {lu}; "
        "saturated = share of samples at an input limit. The worst corner is, per loop, the "
        f"one with the largest ME of the {b.corners} corners of {_box_text(b, params)}."
        if rule is not None
        else "No baseline rows."
    )
    header = ["loop", f"ME ({lu})", f"MAXE ({lu})", f"RMSE ({lu})", "saturated (%)"]
    header += [f"worst ME ({lu})", f"worst MAXE ({lu})", f"worst RMSE ({lu})", "worst sat. (%)"]
    rows = [[r.label, *_cells(r.nominal), *_cells(r.worst)] for r in b.rows]
    doc.table(header, rows, id="baselines")
    gone = [f"{r.label}: {r.nominal.status}" for r in b.rows if r.nominal.status.startswith("not")]
    if gone:
        doc.para("Not run: " + "; ".join(gone) + ".")
    doc.para(
        winner_sentence(b.nominal_winner, "On the nominal model", lu)
        + " "
        + winner_sentence(b.worst_winner, "At the worst corner", lu)
    )
    lines = []
    for r in b.rows:
        lines += [f"# {r.label}, nominal", r.nominal.command_text]
        lines += [f"# {r.label}, worst corner {r.worst.corner}", r.worst.command_text]
    doc.para("Each number is reproduced by the command below its row's label:")
    doc.pre("\n".join(lines))
