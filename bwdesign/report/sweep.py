"""The sweep report: the scenario table's statistics, histograms and the worst scenario replayed."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..output.files import DirectoryTarget
from ..sim.replay import SENSITIVE_RTOL, SENSITIVITY_STEP, RowReplay, replay_row
from ..sim.sweep import SweepSpec
from ..study import Study
from ..study.sweep import sweep_summary
from .document import Document
from .figures import FigureWriter, as_writer

__all__ = ["sweep_document", "sweep_section", "write_sweep"]


def _quantile_table(doc: Document, summary: Mapping[str, Any]) -> None:
    header = ["observer", "unstable", "outside the envelope"] + [
        f"{m.upper()} {q}" for m in ("me", "maxe", "rmse") for q in ("p50", "p90", "p99", "max")
    ]
    body = []
    for obs, s in summary.items():
        row = [
            obs.upper(),
            f"{s['unstable']} ({100 * s['fraction_unstable']:.2f} %)",
            "-"
            if s["outside_envelope"] is None
            else f"{s['outside_envelope']} ({100 * s['fraction_outside_envelope']:.2f} %)"
            + ("" if not s["outside_envelope"] else f", up to {s['worst_envelope_ratio']:.3g}x"),
        ]
        for m in ("me", "maxe", "rmse"):
            row += (
                ["-"] * 4
                if s[m] is None
                else [f"{s[m][k]:.4g}" for k in ("p50", "p90", "p99", "max")]
            )
        body.append(row)
    doc.table(header, body)


def sweep_section(doc: Document, study: Study, figs: FigureWriter | Path) -> None:
    """The certified-gains report's ``[sweep]`` section (:attr:`Study.sweep`).

    The histogram figure is written into ``figs`` (a folder, or a
    :class:`~bwdesign.report.figures.FigureWriter`).
    """
    figs = as_writer(figs)

    part = study.sweep
    spec, bounds, summary = part.spec, part.bounds, part.summary
    seed, n, dist = part.seed, part.samples, part.distribution
    lu = spec.params.length_unit
    doc.heading("Robustness over the uncertainty box (Monte Carlo)")
    box = ", ".join(f"{k} in [{lo:.6g}, {hi:.6g}]" for k, (lo, hi) in bounds.items())
    doc.para(
        f"{n} scenarios drawn {dist} from the [uncertainty] box ({box}), seed {seed}; the "
        f"{part.tuning} tuning, sensor noise {spec.noise_std:g} {lu}, "
        f"{spec.duration:g} s per scenario, starting "
        f"{'on the reference' if spec.start == 'reference' else 'from rest'}; metrics over "
        "the last two "
        "reference periods. The same sweep, larger: `bwdesign sweep --config "
        f"{Path(study.config.source).name} --samples N --seed {seed} --tuning "
        f"{part.tuning} --noise-std {spec.noise_std:g} --out DIR`."
    )
    _quantile_table(doc, summary)
    _envelope_para(doc, spec, summary, n, replays=False)

    def draw() -> Any:
        from ..plotting.sweep import plot_sweep_histograms

        return plot_sweep_histograms(dict(part.table), length_unit=lu, title="stable scenarios")[0]

    figs.save("sweep_histograms.png", draw)
    doc.figure(f"{figs.name}/sweep_histograms.png", f"ME, MAXE and RMSE ({lu}) over the scenarios")


def sweep_document(
    spec: SweepSpec,
    table: Mapping[str, np.ndarray],
    *,
    out_dir: Path,
    settings: Mapping[str, Any],
) -> tuple[Document, dict[str, Any]]:
    """Build the report; figures are written under ``out_dir/figures`` (a staging path).

    The box table lists the parameters ``spec.box`` varies.
    """
    from ..plotting import figures as plotting
    from ..plotting.sweep import plot_sweep_histograms

    lu = spec.params.length_unit
    bounds = spec.box.check(spec.params)
    summary = sweep_summary(table, udot_max=spec.udot_max)
    doc = Document(title=f"Monte Carlo sweep: {spec.params.name or 'stage'}")
    n = len(np.unique(table["scenario"]))
    doc.para(
        f"{n} scenarios, seed {settings['seed']}, {settings['distribution']} in the box below; "
        f"observers {', '.join(o.upper() for o in spec.observers)}; {spec.reference.describe()}; "
        f"dt = {spec.dt:g} s, {spec.duration:g} s per scenario, sensor noise "
        f"{spec.noise_std:g} {lu} (seeded per scenario), "
        f"{'one-sample delay, ' if spec.delay else ''}"
        f"controller {spec.controller.to_dict()['form']} "
        f"(lambda1 = {spec.controller.lambda1:g}, lambda2 = {spec.controller.lambda2:g})"
        + _baselines_text(spec)
        + ". Metrics over the last two reference periods. Rows: scenarios.parquet."
    )
    doc.heading("Uncertainty box")
    rows = [
        [k, f"{getattr(spec.params, k):.6g}", f"{lo:.6g}", f"{hi:.6g}"]
        for k, (lo, hi) in bounds.items()
    ]
    doc.table(["parameter", "nominal", "low", "high"], rows or [["(none)", "", "", ""]])
    doc.heading("Tracking error over the scenarios")
    _quantile_table(doc, summary)
    figs = out_dir / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    fig, _ = plot_sweep_histograms(dict(table), length_unit=lu, title="stable scenarios")
    plotting.save_figure(fig, figs / "histograms.png")
    doc.figure("figures/histograms.png", f"ME, MAXE and RMSE ({lu}) of the stable scenarios")
    doc.heading("Input rate and the certified envelope")
    _envelope_para(doc, spec, summary, n)
    doc.heading("Worst scenarios, replayed")
    doc.para(
        "Each observer's worst row replayed with simulate(), then replayed once more with "
        f"a1 changed by {SENSITIVITY_STEP:g} (relative): where the loop is insensitive to "
        "rounding both agree with the row to rounding; where it is sensitive (chaotic), "
        "they differ by far more, and such rows reproduce only statistically (the same "
        "sweep command on the same machine reproduces them bit for bit)."
    )
    for obs, s in summary.items():
        unstable = table["scenario"][(table["observer"] == obs) & ~table["stable"]]
        worst = (
            int(unstable[0])
            if unstable.size
            else (None if s["me"] is None else s["me"]["worst_scenario"])
        )
        if worst is None:
            continue
        i = int(np.flatnonzero(table["scenario"] == worst)[0])
        rep = replay_row(spec, table, worst, obs)
        s["replay"] = rep.to_dict()
        what = "the first unstable scenario" if unstable.size else "the largest ME"
        drawn = ", ".join(f"{k} = {float(table[k][i]):.6g}" for k in bounds) or "nominal"
        doc.para(
            f"{obs.upper()}: scenario {worst} ({what}; {drawn}; noise seed "
            f"{int(table['noise_seed'][i])}): {_replay_text(rep, lu, spec.params.input_unit)}"
        )
        run = rep.run
        fig, _ = plotting.plot_simulation(run, title=f"{obs.upper()}, scenario {worst}")
        name = f"worst_{obs}.png"
        plotting.save_figure(fig, figs / name)
        doc.figure(f"figures/{name}", f"{obs.upper()} scenario {worst} replayed with simulate()")
    doc.heading("Robust certificate")
    doc.para(
        "No robust certificate (a certified error bound over the uncertainty box) exists for "
        "this configuration yet, so the sweep's worst case is not compared with one."
    )
    return doc, summary


def _baselines_text(spec: Any) -> str:
    """What the baseline rows run (they have no observer and not the eq. (12) law)."""
    rows = []
    for name in spec.observers:
        c = spec.loop_for(name).controller
        if getattr(c, "form", None) == "baseline":
            gains = f"kp = {c.kp:.4g}, ki = {c.ki:.4g}" + (f", kd = {c.kd:.4g}" if c.kd else "")
            rows.append(f"{name.upper()} {gains}")
    if not rows:
        return ""
    return (
        "; baselines (no observer, tuned by the phase-margin rule of "
        "bwdesign.control.baseline_tuning): " + "; ".join(rows)
    )


def _metrics_text(m: Mapping[str, float] | None, lu: str, iu: str) -> str:
    if m is None:
        return "diverged"
    rate = f"|u'| up to {m['input_rate_max']:.4g} {iu}/s"
    return f"ME {m['me']:.6g}, MAXE {m['maxe']:.6g} {lu}, {rate}"


def _relative(d: float | None) -> str:
    if d is None or math.isinf(d):
        return "a run that diverged where the other did not"
    return f"up to {d:.2g}, relative"


def _replay_text(rep: RowReplay, lu: str, iu: str) -> str:
    """The row, its replay, the perturbed replay and what that says about the row."""
    if rep.sensitive is None:
        return f"diverged in the sweep and in the replay ({rep.run.status})."
    text = (
        f"row {_metrics_text(rep.row, lu, iu)}; replayed with simulate(): "
        f"{_metrics_text(rep.replayed, lu, iu)} (ME and MAXE differ from the row by "
        f"{_relative(rep.replay_difference)}); with a1 x (1 + {SENSITIVITY_STEP:g}): "
        f"{_metrics_text(rep.perturbed, lu, iu)} ({_relative(rep.perturbation_change)} from the "
        "replay). "
    )
    if rep.sensitive:
        return text + (
            f"This loop is sensitive to rounding (above {SENSITIVE_RTOL:g}): its row "
            "reproduces only statistically, not digit for digit."
        )
    return text + f"Replay and row agree (within {SENSITIVE_RTOL:g}): the row reproduces."


def _envelope_para(
    doc: Document, spec: SweepSpec, summary: Mapping[str, Any], n: int, *, replays: bool = True
) -> None:
    """How far each observer's input rate left the envelope the certificate assumed."""
    iu = spec.params.input_unit
    rates = []
    for obs, s in summary.items():
        r = s["input_rate_max"]
        if r is None:
            rates.append(f"{obs.upper()}: no stable scenario")
        elif s["outside_envelope"] is None:
            rates.append(f"{obs.upper()} up to {r['max']:.4g} {iu}/s")
        else:
            rates.append(
                f"{obs.upper()} up to {r['max']:.4g} {iu}/s ({s['worst_envelope_ratio']:.3g}x the "
                f"envelope, scenario {r['worst_scenario']}): {s['outside_envelope']} of {n} "
                f"scenarios ({100 * s['fraction_outside_envelope']:.2f} %) outside"
            )
    measured = (
        "Largest |u'| (|u_k - u_(k-1)| / dt) over the metrics window: " + "; ".join(rates) + "."
    )
    if spec.udot_max is None:
        doc.para(f"{measured} No envelope to compare with: {spec.envelope_source}.")
        return
    outside = sum(s["outside_envelope"] or 0 for s in summary.values())
    doc.para(
        f"The certificates of this loop assume |u'| <= {spec.udot_max:.4g} {iu}/s "
        f"({spec.envelope_source}). {measured}"
        + (
            " The rows outside (within_envelope = false in scenarios.parquet) are outside "
            "every certified statement: their errors are simulated, not covered. There the "
            "loop's input chatters and the loop can be chaotic, so those rows reproduce only "
            "statistically" + (" (see the replays below)." if replays else ".")
            if outside
            else " Every stable scenario stayed inside it."
        )
    )


def write_sweep(
    target: DirectoryTarget,
    spec: SweepSpec,
    table: Mapping[str, np.ndarray],
    settings: Mapping[str, Any],
) -> dict[str, Any]:
    """Write ``scenarios.parquet``, ``summary.json``, ``report.md``/``.html`` and figures.

    ``target`` comes from :func:`bwdesign.output.prepare_directory` (checked before
    the sweep ran). Returns the summary (per observer: unstable count, quantiles).
    """
    from ..output.jsonenc import dump_json

    pa, pq = _pyarrow()
    with target.stage() as stage:
        columns = {k: (v.tolist() if v.dtype == object else v) for k, v in table.items()}
        pq.write_table(pa.table(columns), stage.file("scenarios.parquet"))
        doc, summary = sweep_document(spec, table, out_dir=stage.root, settings=settings)
        bounds = spec.box.check(spec.params)
        stage.write_text(
            "summary.json",
            dump_json({"summary": summary, "bounds": bounds, "settings": dict(settings)}) + "\n",
        )
        stage.write_text("report.md", doc.to_markdown())
        stage.write_text("report.html", doc.to_html(stage.root))
    return summary


def _pyarrow():
    from ..extras import require

    feature = "writing scenarios.parquet"
    return require("pyarrow", extra="sweep", feature=feature), require(
        "pyarrow.parquet", extra="sweep", feature=feature
    )
