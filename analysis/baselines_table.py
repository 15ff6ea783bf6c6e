"""The baselines beside the observer loops, for several references (issue 29's closing table).

Run with ``.venv/bin/python analysis/baselines_table.py --out reports/baselines`` (part of
``make paper``; about two minutes for ``paper_experiment``). For the stage's reference
shape and size, a sine and a triangle at 1 Hz and at 20 Hz (each only when the exact
inverse's input stays inside the stage's ``[controller]`` limits), it computes the study's
comparison (:func:`bwdesign.study.baselines.baseline_comparison`, the function behind the
report's "Baselines" section: the four tuned baselines and the six observer loops, nominal
and at each loop's worst corner of ``[uncertainty]`` or of the default +-2 %/+-10 % box)
and writes ``baselines.md`` (one table per reference, the winner sentences and every
reproducing command) and ``baselines.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from bwdesign import Sine, Triangle, derive_envelope, load_config
from bwdesign.design.tuning import digital_tuning
from bwdesign.output.files import prepare_directory
from bwdesign.report.baselines import winner_sentence
from bwdesign.study.baselines import baseline_comparison

FREQUENCIES = (1.0, 20.0)  # Hz


def log(msg: str) -> None:
    print(f"[baselines] {msg}", file=sys.stderr, flush=True)


def fmt(v: float | None) -> str:
    return "unstable" if v is None else f"{v:.4g}"


def sat(v: float | None) -> str:
    return "no limits" if v is None else f"{100 * v:.3g}"


def references(config):
    """``(label, reference, why-skipped)`` for each shape and frequency."""
    amp, off = config.reference.amplitude, config.reference.offset
    limits = None if config.controller is None else config.controller.input_limits()
    for cls in (Sine, Triangle):
        for f in FREQUENCIES:
            ref = cls(amplitude=amp, offset=off, frequency=f)
            label = f"{ref.to_dict()['kind']} {f:g} Hz"
            why = None
            if limits is not None:
                lo, hi = derive_envelope(config.plant, ref).u_range
                if lo < limits[0] or hi > limits[1]:
                    why = (
                        f"the exact inverse needs {lo:.4g} .. {hi:.4g} V, outside the input "
                        f"limits {limits[0]:g} .. {limits[1]:g} V"
                    )
            yield label, ref, why


def markdown(config, cases: list[tuple[str, object, str | None]]) -> str:
    lu = config.plant.length_unit
    md = [
        f"# Baselines beside the observer loops: {config.plant.name}",
        "",
        "Computed by `analysis/baselines_table.py` with bwdesign.study.baselines."
        "baseline_comparison (the report's Baselines section) for each reference below: "
        "three reference periods from the reference, no noise, no computation delay, metrics "
        f"over the last two periods, in {lu}. Worst = each loop's corner with the largest ME.",
        "",
    ]
    for label, b, why in cases:
        md += [f"## {label}", ""]
        if b is None:
            md += [f"Not run: {why}.", ""]
            continue
        md.append(
            f"Box: {b.box_source} ({b.box.describe(config.plant)}), {b.corners} corners; "
            f"window {b.window[0]:g} .. {b.window[1]:g} s."
        )
        md += ["", "| loop | ME | MAXE | RMSE | sat. (%) | worst ME | worst MAXE | worst RMSE "
               "| worst sat. (%) |", "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for r in b.rows:
            n, w = r.nominal, r.worst
            md.append(
                f"| {r.label} | {fmt(n.me)} | {fmt(n.maxe)} | {fmt(n.rmse)} | {sat(n.saturated)} "
                f"| {fmt(w.me)} | {fmt(w.maxe)} | {fmt(w.rmse)} | {sat(w.saturated)} |"
            )
        md += [
            "",
            winner_sentence(b.nominal_winner, "On the nominal model", lu)
            + " "
            + winner_sentence(b.worst_winner, "At the worst corner", lu),
            "",
            "```",
        ]
        for r in b.rows:
            md += [f"# {r.label}, nominal", r.nominal.command_text]
            md += [f"# {r.label}, worst corner", r.worst.command_text]
        md += ["```", ""]
    return "\n".join(md)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default="configs/paper_experiment.toml", help="stage file")
    ap.add_argument("--out", default="reports/baselines", help="output directory")
    args = ap.parse_args(argv)
    config = load_config(args.config)
    target = prepare_directory(args.out, command="analysis baselines_table", what="--out")
    with target.stage() as stage:
        return _run(config, stage.root)


def _run(config, out: Path) -> int:
    tuning = digital_tuning(config.plant, config.dt)
    cases, doc = [], {}
    for label, ref, why in references(config):
        t0 = time.perf_counter()
        b = None
        if why is None:
            b = baseline_comparison(config, gains=config.gains, tuning=tuning, reference=ref)
            doc[label] = b.to_dict()
        else:
            doc[label] = {"skipped": why}
        cases.append((label, b, why))
        log(f"{label}: {time.perf_counter() - t0:.0f} s")
    (out / "baselines.md").write_text(markdown(config, cases))
    (out / "baselines.json").write_text(json.dumps(doc, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
