"""The identification report: one fit in, Markdown + HTML (+ JSON, figures) out.

Same document model as the certified-gains report
(:class:`bwdesign.report.document.Document`): measured vs model over time,
the hysteresis loop, residual autocorrelation and spectrum, the parameter
table with intervals, the correlation matrix and the diagnostics.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .._version import __version__
from ..identify.result import Z95, IdentificationResult
from ..output.files import DirectoryTarget, prepare_directory
from ..output.jsonenc import dump_json
from .document import Document

__all__ = ["identification_document", "write_identification_report"]

NAMES = ("a1", "a2", "a3", "alpha", "beta", "gamma")
UNITS = {
    "a1": "1/s^2",
    "a2": "1/s",
    "a3": "um/(V s^2)",
    "alpha": "um/V",
    "beta": "1/V",
    "gamma": "1/V",
}


def _g(v: float, digits: int = 6) -> str:
    return "not determined" if not math.isfinite(v) else f"{v:.{digits}g}"


def identification_document(
    result: IdentificationResult, *, figures: dict[str, str], stage_file: str | None = None
) -> Document:
    """Build the report's blocks (figures by relative path)."""
    p = result.params
    doc = Document(f"Identification report: {p.name or 'stage'}")
    fp = result.fit_percent
    val = f"{fp['validation']:.3f} %" if fp["validation"] is not None else "no validation record"
    bad = [n for n in NAMES if not result.determined[n]]
    verdict = (
        f"Fit {fp['train']:.3f} % (training), {val} (validation); residual RMS "
        f"{result.residual_rms:.4g} um. "
        + (
            f"NOT determined by the record: {', '.join(bad)}."
            if bad
            else "Every parameter determined."
        )
    )
    doc.verdict(
        verdict if result.converged else f"DID NOT CONVERGE: {result.reason}. {verdict}",
        ok=result.converged and not bad,
    )
    if stage_file:
        doc.para(
            f"Stage file: `{stage_file}` ([plant], [sampling], [uncertainty] with these 95 % "
            f"intervals). Certify gains for it with `bwdesign report --config {stage_file} "
            "--out DIR` after replacing its placeholder [reference]."
        )
    if result.diagnostics:
        doc.heading("Diagnostics")
        doc.bullets(list(result.diagnostics))
    doc.heading("Parameters")
    rows = []
    for n in NAMES:
        v, se = getattr(p, n), result.std_err[n]
        lo, hi = result.ci95[n]
        rel = 1.96 * se / abs(v) if math.isfinite(se) and v else math.inf
        rows.append(
            [
                n,
                f"{v:.6g}",
                UNITS[n],
                _g(se, 3),
                f"[{_g(lo)}, {_g(hi)}]" if math.isfinite(lo) else "not determined",
                "yes" if result.determined[n] else "**no**",
                "inf" if not math.isfinite(rel) else f"{100 * rel:.3g} %",
            ]
        )
    doc.table(
        ["parameter", "value", "unit", "std. error", "95 % interval", "determined", "± (rel.)"],
        rows,
        id="params",
    )
    d = result.derived
    doc.table(
        ["derived quantity", "value", "std. error"],
        [
            [
                "static gain a3/a1 (um/V)",
                f"{d['static_gain']['value']:.6g}",
                _g(d["static_gain"]["std_err"], 3),
            ],
            ["lag a2/a1 (s)", f"{d['lag']['value']:.6g}", _g(d["lag"]["std_err"], 3)],
            [
                "natural frequency (Hz)",
                f"{d['natural_frequency']['value']:.6g}",
                _g(d["natural_frequency"]["std_err"], 3),
            ],
            [
                "damping ratio",
                f"{d['damping_ratio']['value']:.4g}",
                _g(d["damping_ratio"]["std_err"], 3),
            ],
            ["sensor offset (um)", f"{result.offset:.6g}", _g(result.offset_std_err, 3)],
            ["input delay (samples)", str(result.delay_samples), "-"],
        ],
    )
    doc.para(f"Intervals: {result.covariance_method}.")
    if len(result.records) > 1 or len(result.validation_records) > 1:
        _records_table(doc, result)
    if result.extensions:
        _extensions_section(doc, result)
    doc.heading("Correlation matrix")
    corr = result.correlation
    doc.table(
        ["", *NAMES],
        [
            [n] + ["-" if not np.isfinite(c) else f"{c:+.3f}" for c in corr[i]]
            for i, n in enumerate(NAMES)
        ],
        id="correlation",
    )
    doc.heading("Measured and model")
    doc.figure(figures["time"], "Displacement over time, measured and model, and the residual.")
    doc.figure(figures["loop"], "Hysteresis loop u vs y, measured and model.")
    doc.heading("Residuals")
    doc.figure(
        figures["residuals"],
        "Residual autocorrelation (dotted: the ±2/sqrt(N) band of white noise) and spectrum.",
    )
    doc.heading("Reproducibility")
    doc.pre(
        f"bwdesign {__version__}\nsamples {result.n_samples}, dt {result.dt!r} s\n"
        f"starts {result.n_starts}, residual evaluations {result.nfev}, "
        f"{result.seconds:.2f} s\nconverged {result.converged}: {result.reason}"
    )
    return doc


def _pct_or_dash(v: float | None, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def _extensions_section(doc: Document, result: IdentificationResult) -> None:
    """Fit and residual whiteness with and without each extension, the disturbance
    bound and the coverage."""
    ext = result.extensions
    doc.heading("Model extensions")
    doc.para(
        f"Chosen: {', '.join(ext['chosen']) or 'none'}. {ext['criterion']}. The [plant] "
        "parameters are the Bouc-Wen part of the chosen fit. Whiteness: lag-1 residual "
        "autocorrelation and the share of lags 1-50 outside the ±2/sqrt(N) band (about 5 % "
        "for white noise). Rows screened out show the fit after one Gauss-Newton step."
    )
    rows = []
    for label, row in [("base model", ext["base"]), ("chosen model", ext["final"])] + [
        (f"+ {name}", r) for name, r in ext["candidates"].items()
    ]:
        rows.append(
            [
                label,
                _pct_or_dash(row.get("fit_train")),
                _pct_or_dash(row.get("fit_heldout")),
                _pct_or_dash(row.get("acf1")),
                _pct_or_dash(None if "frac_out" not in row else 100 * row["frac_out"], 0),
                _pct_or_dash(row.get("delta_bic"), 1),
                row.get("reason", "-"),
            ]
        )
    doc.table(
        [
            "model",
            "fit train (%)",
            "fit held-out (%)",
            "lag-1 acf",
            "lags outside (%)",
            "BIC change",
            "decision",
        ],
        rows,
        id="extensions",
    )
    if result.disturbance is None:
        return
    how, dist = result.unexplained, result.disturbance
    band = how["band"]
    cov = "not measured" if result.coverage is None else f"{100 * result.coverage:.2f} %"
    nominal = ", ".join(band["nominal_for"])
    doc.heading("Unexplained behaviour and coverage")
    doc.para(
        f"Input-equivalent disturbance bound [uncertainty.disturbance]: input_max = "
        f"{dist.input_max:.4g}, rate_max = {dist.rate_max:.4g} per s ({dist.source}). Rule: "
        f"{how['rule']}; window {1e3 * how['window_s']:g} ms (at least "
        f"{how['min_window_samples']} samples); static gain {how['static_gain']:.6g} um/V; "
        f"sensor noise (fast remainder) {how['noise_std']:.3g} um."
    )
    full = band.get("coverage_full_bound")
    doc.para(
        f"Coverage on the {band['heldout']}: {cov} of the samples lie inside the band over "
        f"{band['corners']} corner(s) of the [uncertainty] box"
        + (f" ({nominal} held at nominal: infinite half-width)" if nominal else "")
        + f", widened by the bound from the training records alone (input_max "
        f"{band['input_max_training']:.4g}) through the static gain plus "
        f"{band['noise_sigmas']:g} sigma of sensor noise."
        + (
            f" With the bound written to the stage file (taken over the validation records "
            f"too; band ±{band['half_width']:.4g} um) the share is {100 * full:.2f} %."
            if full is not None
            else ""
        )
    )


def _records_table(doc: Document, result: IdentificationResult) -> None:
    """Per record: fit percent, residual RMS and (training) the sensor offset."""
    doc.heading("Records")
    doc.para(
        f"{len(result.records)} training record(s) fitted together: one parameter set, a "
        "sensor offset and an initial state per record (offsets with 95 % half-widths); "
        "validation records re-estimate their own offset and initial state."
    )
    rows = []
    for role, recs in (("training", result.records), ("validation", result.validation_records)):
        for rec in recs:
            offset = (
                f"{rec['offset']:.6g} ± {Z95 * rec['offset_std_err']:.2g}"
                if "offset" in rec
                else "-"
            )
            rows.append(
                [
                    role,
                    f"`{rec['source'] or 'record'}`",
                    str(rec["n_samples"]),
                    f"{rec['dt']:.6g}",
                    f"{rec['fit_percent']:.3f}",
                    f"{rec['residual_rms']:.4g}",
                    offset,
                ]
            )
    doc.table(
        ["record", "source", "samples", "dt (s)", "fit (%)", "residual RMS (um)", "offset (um)"],
        rows,
        id="records",
    )


def write_identification_report(
    result: IdentificationResult,
    target: DirectoryTarget | str | Path,
    *,
    stage_file: str | Path | None = None,
) -> Path:
    """Write report.md, report.html, identification.json and PNG figures.

    ``target``: a directory from :func:`bwdesign.output.prepare_directory` (checked
    before the fit), or a path, checked here; written through the output layer.

    Raises
    ------
    OutputError
        The directory holds files bwdesign did not write, or cannot be written.
    """
    from ..plotting.figures import save_figure
    from ..plotting.identification import plot_fit_loop, plot_fit_time, plot_residuals

    if not isinstance(target, DirectoryTarget):
        target = prepare_directory(target, command="identify --report", what="report directory")
    with target.stage() as stage:
        tr = result.traces
        figs = {"time": "fit_time.png", "loop": "fit_loop.png", "residuals": "residuals.png"}
        for key, fig in (
            ("time", plot_fit_time(tr, title=result.params.name)[0]),
            ("loop", plot_fit_loop(tr)[0]),
            ("residuals", plot_residuals(tr["y"] - tr["y_model"], result.dt)[0]),
        ):
            save_figure(fig, stage.file(figs[key]))
        doc = identification_document(
            result, figures=figs, stage_file=str(stage_file) if stage_file else None
        )
        stage.write_text("report.md", doc.to_markdown())
        stage.write_text("report.html", doc.to_html(stage.root))
        stage.write_text("identification.json", dump_json(result.to_dict()) + "\n")
    return target.path
