"""The identification report of the structural form: Markdown + HTML + JSON + figures.

The same document model and figures as the piezo form's report
(:mod:`bwdesign.report.identification`): what the data determine with intervals,
what they do not, the validation scores, measured against model.
"""

from __future__ import annotations

from pathlib import Path

from .._version import __version__
from ..identify.structural import DETERMINED, StructuralFit
from ..output.files import DirectoryTarget, prepare_directory
from ..output.jsonenc import dump_json
from .document import Document

__all__ = ["structural_document", "write_structural_report"]


def structural_document(
    fit: StructuralFit, *, figures: dict[str, str], stage_file: str
) -> Document:
    """The report's blocks (figures by relative path)."""
    p = fit.params
    lu, iu = p.length_unit, p.input_unit
    doc = Document(f"Identification report: {p.name or 'stage'} (structural Bouc-Wen form)")
    fp = fit.fit_percent
    val = (
        f"validation RMS error {fit.residual_rms_validation:.4g} {lu}"
        if fit.residual_rms_validation is not None
        else "no validation record"
    )
    text = (
        f"Fit {fp['train']:.4f} % (training), residual RMS {fit.residual_rms:.4g} {lu}; {val}. "
        "Determined: m, c, k, alpha, beta*gamma, beta*delta; beta, gamma and delta apart are "
        "not determined by any record."
    )
    doc.verdict(
        text if fit.converged else f"DID NOT CONVERGE: {fit.reason}. {text}", ok=fit.converged
    )
    doc.para(f"Stage file: `{stage_file}`. Identification time {fit.seconds:.1f} s.")
    doc.heading("What the data determine")
    units = {
        "m": f"{iu} s^2/{lu}",
        "c": f"{iu} s/{lu}",
        "k": f"{iu}/{lu}",
        "alpha": f"{iu}/{lu}",
        "beta_gamma": f"1/{lu}",
        "beta_delta": f"1/{lu}",
    }
    rows = [
        [n, f"{fit.values[n]:.8g}", f"[{fit.ci95[n][0]:.8g}, {fit.ci95[n][1]:.8g}]", units[n]]
        for n in DETERMINED
    ]
    rows.append(["beta, gamma, delta apart", "not determined", "-", "-"])
    doc.table(["parameter", "value", "95 % interval", "unit"], rows, id="parameters")
    doc.para(
        "beta multiplies gamma and delta everywhere in the model, so only the products are "
        "determined; the stage file carries beta = 1 as a convention."
    )
    if fit.validation:
        doc.heading("Validation")
        doc.table(
            ["record", "fit %", f"RMS error ({lu})"],
            [
                [v["source"], f"{v['fit_percent']:.4f}", f"{v['rms_error']:.4g}"]
                for v in fit.validation
            ],
            id="validation",
        )
    doc.heading("Measured and model")
    doc.figure(figures["time"], "Displacement over time, measured and model, and the residual.")
    doc.figure(figures["loop"], "Force against displacement, measured and model.")
    doc.heading("Reproducibility")
    doc.pre(
        f"bwdesign {__version__}\ndt {fit.dt!r} s, periodic {fit.periodic}\n"
        f"{fit.seconds:.2f} s\nconverged {fit.converged}: {fit.reason}"
    )
    return doc


def write_structural_report(
    fit: StructuralFit, target: DirectoryTarget | str | Path, *, stage_file: str | Path
) -> Path:
    """Write report.md, report.html, identification.json and PNG figures (output layer)."""
    from ..plotting.figures import save_figure
    from ..plotting.identification import plot_fit_loop, plot_fit_time

    if not isinstance(target, DirectoryTarget):
        target = prepare_directory(target, command="identify --report", what="report directory")
    lu, iu = fit.params.length_unit, fit.params.input_unit
    with target.stage() as stage:
        figs = {"time": "fit_time.png", "loop": "fit_loop.png"}
        tr = fit.traces
        save_figure(
            plot_fit_time(tr, title=fit.params.name, length_unit=lu)[0], stage.file(figs["time"])
        )
        save_figure(plot_fit_loop(tr, length_unit=lu, input_unit=iu)[0], stage.file(figs["loop"]))
        doc = structural_document(fit, figures=figs, stage_file=str(stage_file))
        stage.write_text("report.md", doc.to_markdown())
        stage.write_text("report.html", doc.to_html(stage.root))
        stage.write_text("identification.json", dump_json(fit.to_dict()) + "\n")
    return target.path
