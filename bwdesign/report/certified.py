"""The certified-gains report: a rendering of a stage's computed study.

:func:`write_report` computes the :class:`~bwdesign.study.Study` of a
:class:`~bwdesign.model.config.StageConfig` (:func:`bwdesign.study.study`) and
writes a directory holding ``report.md``, a self-contained ``report.html``,
``certificate.json`` (the study's :meth:`~bwdesign.study.Study.to_dict`) and
``figures/*.png``. :func:`render` turns a study into the document: prose, tables
and the figures, drawn from the study's data; it computes nothing. The
directory is written through :mod:`bwdesign.output.files`: staged inside the
target and moved into place at the end, so an error never leaves a half-written
report, and no file bwdesign did not write is ever touched.
"""

from __future__ import annotations

import os
import shlex
import sys
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..certify.results import CertificateReport
from ..errors import InputError
from ..model.config import StageConfig
from ..model.stage_presets import STAGES_DIR
from ..output.files import prepare_directory
from ..output.jsonenc import dump_json
from ..output.text import gains_text, limits_text
from ..study import REPORT_PARTS, Study, study
from ..study.cache import StudyCache
from .baselines import baselines_section
from .document import Document, fmt
from .figures import FigureWriter, as_writer, keep_figures, kept_figures
from .robust import robust_section
from .summary import summary_block
from .sweep import sweep_section
from .tiers import tier_synthesis_section
from .tracking import tracking_section

__all__ = ["ReportOutcome", "build_report", "render", "write_report", "TIER_MEANING"]

#: Files every report holds (checked against foreign files before any work).
REPORT_FILES = ("report.md", "report.html", "certificate.json")

TIER_MEANING = {
    "theorem1": (
        "The paper's Theorem 1 with the sign corrected (2L||P|| < 1, P from the Lyapunov "
        "equation, L = (|beta| + |gamma|) |u'|max). Sound but very conservative: the plant "
        "couples eps3 into eps2 through a1, which makes ||P|| huge."
    ),
    "lipschitz": (
        "Bounded-real (S-procedure) LMI using only |phi~| <= L |eps3|; equivalent to "
        "||e3'(sI - A)^-1 e3||_inf < 1/L. Ignores the sign of the hysteresis error."
    ),
    "sector": (
        "Common quadratic Lyapunov function at both ends of the sector "
        "k in [min(0, (beta - |gamma|) v), max(0, (beta + |gamma|) v)]: uses the fact that "
        "the hysteresis error is dissipative when beta >= |gamma|. Certifies the continuous "
        "observer."
    ),
    "sampled": (
        "The same question for the observer that actually runs at dt (exact ZOH model, "
        "hysteresis jump map with slope rho in a certified interval): the certificate for "
        "the code on the stage."
    ),
}


@dataclass(frozen=True)
class ReportOutcome:
    """What :func:`write_report` produced.

    Attributes
    ----------
    out_dir : Path
    certified : bool
        The configured gains (if any) are certified, synthesis is feasible and
        the reference's feedforward input stays within ``[controller]
        u_min/u_max`` (the exit code of ``bwdesign report`` follows it).
    verdict : str
        The sentence at the top of the report.
    """

    out_dir: Path
    certified: bool
    verdict: str


def _tier_cell(rep: CertificateReport | None, name: str) -> list[str]:
    if rep is None:
        return ["-", "-", "-", "-"]
    try:
        c = rep.tier(name)
    except KeyError:
        return ["-", "-", "-", "-"]
    worst = min((m.limit - m.value for m in c.margins), default=None) if c.holds else None
    env = fmt(c.max_udot) + (" (search limit)" if c.max_udot_capped else "")
    return [
        "**yes**" if c.holds else "no",
        env,
        fmt(c.decay_rate),
        fmt(worst, 3) if worst is not None else "-",
    ]


def _progress(quiet: bool) -> Callable[[str], None] | None:
    def say(msg: str) -> None:
        print(f"[report] {msg}", file=sys.stderr, flush=True)

    return None if quiet else say


# -- sections ------------------------------------------------------------------------


def _plant_section(doc: Document, s: Study) -> None:
    params, summ = s.config.plant, s.plant
    lu, iu = params.length_unit, params.input_unit
    doc.heading("Plant")
    units = {
        "a1": "1/s^2",
        "a2": "1/s",
        "a3": f"{lu}/({iu} s^2)",
        "alpha": f"{lu}/{iu}",
        "beta": f"1/{iu}",
        "gamma": f"1/{iu}",
    }
    rows = [[k, f"{getattr(params, k):.8g}", u] for k, u in units.items()]
    if params.physical is not None:
        for k in ("m", "b", "k", "d", "alpha0"):
            rows.append([k, f"{getattr(params.physical, k):.8g}", "physical"])
    rows += [
        ["natural frequency sqrt(a1)/(2 pi)", f"{summ.natural_frequency_hz:.6g}", "Hz"],
        ["damping ratio a2/(2 sqrt(a1))", f"{summ.damping_ratio:.4g}", "-"],
        ["static gain a3/a1", f"{summ.static_gain:.6g}", summ.static_gain_unit],
    ]
    doc.table(["quantity", "value", "unit"], rows)
    doc.para(f"Bounded class: **{'yes' if summ.bounded else 'no'}**. {summ.bounded_reason}.")
    if summ.note is not None:
        doc.para(summ.note)


def _envelope_section(doc: Document, s: Study) -> None:
    config, env, inp = s.config, s.envelope, s.input
    iu, v, dt = config.plant.input_unit, s.envelope.udot_max, float(config.dt)
    doc.heading("Operating envelope")
    erows = [
        ["|u'| bound used by the certificates", f"{v:.6g} {iu}/s"],
        ["sample time dt", f"{dt * 1e3:.6g} ms"],
        ["source", env.source],
    ]
    if env.derived is not None:
        erows += [
            ["reference", config.reference.describe()],
            ["exact-inverse max |u'|", f"{env.derived:.6g} {iu}/s"],
            ["leading order (a1/a3) max |x_d'|", f"{env.leading_order:.6g} {iu}/s"],
            ["margin", f"{env.margin:g}"],
        ]
    need = inp.feedforward
    erows += [
        [
            "feedforward input range (exact inverse)",
            "-" if need is None else f"{need[0]:.4g} .. {need[1]:.4g} {iu}",
        ],
        ["input limits ([controller] u_min, u_max)", limits_text(inp.limits, iu)],
        [
            "feedforward within the limits",
            "-" if inp.within_limits is None else fmt(inp.within_limits),
        ],
    ]
    doc.table(["item", "value"], erows)
    doc.para(
        f"How: {env.method}. Per sample the certificates bound the input jump by "
        f"|u'| dt = {v * dt:.4g} {iu}."
    )


def _decays(s: Study) -> tuple[float, float]:
    """The decays the configured and the synthesised gains are certified at (1/s)."""
    synth = s.synthesis.result
    c_decay = 0.0 if s.configured is None else s.configured.decay
    s_decay = synth.report.decay if synth.report is not None else s.synthesis.decay
    return c_decay, s_decay


def _certificates_section(doc: Document, s: Study) -> None:
    config, configured, synth = s.config, s.configured, s.synthesis.result
    iu = config.plant.input_unit
    doc.heading("Certificates")
    c_decay, s_decay = _decays(s)
    doc.para(
        f"Configured gains l = {gains_text(config.gains)}; synthesised gains "
        f"l = {gains_text(synth.gains)} (discrete K = {gains_text(synth.discrete_gains)}), "
        f"from an LMI synthesis for the {synth.tier} tier asking decay >= "
        f"{s.synthesis.decay:g} 1/s within pole radius {synth.pole_radius:.5g} rad/s. "
        f"Envelope = the largest |u'| ({iu}/s) the tier certifies for those gains with at "
        "least the decay named in the column head; decay = certified exponential rate (1/s) "
        "at the envelope above; check = the smallest slack of the eigenvalue checks made "
        "outside the solver (scaled, > 0 passes). The two sets are certified at different "
        f"required decays (configured: >= {c_decay:g} 1/s; synthesised: >= {s_decay:g} 1/s, "
        "the synthesis request), so their envelopes answer different questions: a larger "
        "required decay certifies a smaller envelope."
    )
    header = [
        "tier",
        f"configured (decay >= {c_decay:g} 1/s): holds",
        "envelope",
        "decay",
        "check",
        f"synthesised (decay >= {s_decay:g} 1/s): holds",
        "envelope",
        "decay",
        "check",
    ]
    crow = []
    for name in ("theorem1", "lipschitz", "sector", "sampled"):
        crow.append([name] + _tier_cell(configured, name) + _tier_cell(synth.report, name))
    doc.table(header, crow, id="certificates")
    doc.bullets([f"`{k}`: {t}" for k, t in TIER_MEANING.items()])
    if configured is not None:
        t1 = configured.tier("theorem1")
        doc.para(f"Theorem 1 for the configured gains: {t1.status}.")


def _error_dynamics_section(doc: Document, s: Study, figs: FigureWriter, plotting: Any) -> None:
    params = s.config.plant
    iu, v = params.input_unit, s.envelope.udot_max
    doc.heading("Observer error dynamics")
    prow = []
    poles_by_label = {}
    for gs in s.error_dynamics:
        ed = gs.dynamics
        for k, p, z in zip(ed.k_interval, ed.poles, ed.damping, strict=True):
            poles = ", ".join(_pole_text(x) for x in p)
            prow.append([gs.label, f"{k:.4g}", poles, ", ".join(f"{x:.3f}" for x in z)])
            poles_by_label[f"{gs.label}, k = {k:.3g}"] = p
    bodes = {gs.label: gs.bode for gs in s.error_dynamics}
    doc.table(["gains", "k (1/s)", "poles of A - k e3 e3' (1/s)", "damping"], prow)
    figs.save(
        "error_poles.png",
        lambda: plotting.plot_error_poles(poles_by_label, title="observer error poles")[0],
    )
    doc.figure(f"{figs.name}/error_poles.png", "Observer error poles at both ends of the sector")
    figs.save(
        "hysteresis_bode.png",
        lambda: plotting.plot_hysteresis_bode(
            bodes, lipschitz_coeff=abs(params.beta) + abs(params.gamma), udot_max=v, input_unit=iu
        )[0],
    )
    doc.figure(
        f"{figs.name}/hysteresis_bode.png",
        "Bode magnitude from the hysteresis error to eps3; its peak sets the lipschitz "
        "envelope 1/((|beta| + |gamma|) peak)",
    )
    doc.para(
        "; ".join(
            f"{k}: H-infinity peak {b.peak:.4g} s at {b.omega_peak:.4g} rad/s, "
            f"lipschitz envelope at decay 0: {b.lipschitz_envelope:.4g} {iu}/s"
            for k, b in bodes.items()
        )
        + f". These are decay-0 bounds: the certificate table's synthesised column asks decay "
        f">= {_decays(s)[1]:g} 1/s, which certifies a smaller envelope."
    )


def _loop_section(doc: Document, s: Study, figs: FigureWriter, plotting: Any) -> None:
    loop, tuning, dt = s.loop, s.tuning, float(s.config.dt)
    doc.heading("Tracking loop")
    lrow = []
    for label, a in (
        ("eq. 12, continuous", loop.continuous),
        ("eq. 12, sampled at dt", loop.sampled),
        ("digital tuning (discrete form), sampled", tuning.nominal),
    ):
        lrow.append(
            [
                label,
                fmt(a.stable),
                fmt(a.max_real_part),
                fmt(a.spectral_radius, 8) if a.spectral_radius is not None else "-",
                fmt(a.gain_margin_db, 3),
                fmt(a.phase_margin, 3),
                fmt(a.delay_margin * 1e3, 3),
            ]
        )
    doc.para(
        f"Configured constants lambda1 = {loop.lambda1:g}, lambda2 = {loop.lambda2:g} "
        f"with observer gains {gains_text(loop.gains)}; the digital tuning chooses "
        f"lambda1 = {tuning.lambda1:.4g}, lambda2 = {tuning.lambda2:.4g}, integral rate "
        f"{fmt(tuning.integral_rate)} 1/s and observer gains "
        f"{gains_text(tuning.gains)} for dt = {dt * 1e3:g} ms."
    )
    doc.table(
        [
            "loop",
            "stable",
            "max Re(s) (1/s)",
            "spectral radius",
            "gain margin (dB)",
            "phase margin (deg)",
            "delay margin (ms)",
        ],
        lrow,
    )
    doc.para(
        f"Digital tuning, worst case over the model mismatch {_mismatch_text(tuning.mismatch)}:"
        " gain margin "
        f"{tuning.worst_gain_margin_db:.3g} dB, phase margin "
        f"{tuning.worst_phase_margin:.3g} deg, delay margin "
        f"{tuning.worst_delay_margin * 1e3:.3g} ms; requirements met: "
        f"{'yes' if tuning.met else 'no'}. {tuning.reasoning}"
    )
    figs.save(
        "loop_poles.png",
        lambda: plotting.plot_loop_poles(
            {"eq. 12 sampled": loop.sampled, "digital tuning": tuning.nominal},
            title="tracking loop poles (z-plane)",
        )[0],
    )
    doc.figure(f"{figs.name}/loop_poles.png", "Closed-loop poles of the sampled tracking loops")


def _firmware_section(doc: Document, s: Study) -> None:
    fw, gains = s.firmware, s.config.gains
    doc.heading("Gains for firmware")
    lines = [
        f"# discrete observer gains at dt = {fw.dt!r} s: x_post = x_prior + K*(z - x_prior[0])"
    ]
    if fw.configured_K is not None:
        lines.append(f"K_configured  = {list(fw.configured_K)!r}")
    if fw.synthesized_K is not None:
        lines.append(f"K_synthesised = {list(fw.synthesized_K)!r}")
    if gains is not None:
        lines.append(
            f"# check: pole matching of l = {list(gains)!r} gives {list(fw.pole_matched)!r}"
        )
    doc.pre("\n".join(lines))


def _reproducibility_section(
    doc: Document, s: Study, date: str | None, out_dir: str | Path | None
) -> None:
    config = s.config
    doc.heading("Reproducibility")
    doc.table(
        ["item", "value"],
        [[k, v_] for k, v_ in s.versions.items()]
        + [
            ["solvers", "Clarabel (fallback SCS); only OPTIMAL is accepted"],
            ["config", Path(config.source).name],
            ["config sha256", config.sha256],
            ["command", _command(config, out_dir, s.allow_unbounded)],
        ],
    )
    doc.para(f"Date: {date or datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}")


def render(
    study: Study,
    figures_dir: str | Path | FigureWriter,
    *,
    date: str | None = None,
    out_dir: str | Path | None = None,
) -> Document:
    """The report of ``study``; its figures are drawn into ``figures_dir``.

    Parameters
    ----------
    study : Study
        With every part the report shows (:data:`bwdesign.study.REPORT_PARTS`).
    figures_dir : path or FigureWriter
        Where the figures are written (created); the document refers to them as
        ``<its name>/<figure>.png``, relative to its parent (the report's directory).
        A :class:`~bwdesign.report.figures.FigureWriter` holding figures drawn before
        for this study writes those instead of drawing them.
    date : str, optional
        The Date line (default: now, UTC).
    out_dir : path, optional
        The report's directory as the user named it, for the reproducibility
        command's ``--out`` (``DIR`` when unknown).

    Raises
    ------
    InputError
        ``study`` lacks a part the report shows.
    """
    from ..plotting import figures as plotting

    if not isinstance(study, Study):
        raise InputError(f"study must be a bwdesign Study, got {type(study).__name__}")
    missing = sorted(REPORT_PARTS - study.parts)
    if missing:
        raise InputError(f"the report needs the study's part(s) {', '.join(missing)}")
    figs = as_writer(figures_dir)
    doc = Document(f"Certified-gains report: {study.name}")
    doc.verdict(study.verdict.text, study.verdict.ok)
    top = len(doc.blocks)  # the summary goes here
    doc.para(
        f"Generated by `bwdesign report` from `{Path(study.config.source).name}`; do not edit. "
        "Every number below is computed from that file."
    )
    _plant_section(doc, study)
    _envelope_section(doc, study)
    _certificates_section(doc, study)
    tier_synthesis_section(doc, study)
    _error_dynamics_section(doc, study, figs, plotting)
    _loop_section(doc, study, figs, plotting)
    tracking_section(doc, study, figs)
    baselines_section(doc, study)
    if study.sweep is not None:
        sweep_section(doc, study, figs)
    if study.robust is not None:
        robust_section(doc, study)
    _firmware_section(doc, study)
    _reproducibility_section(doc, study, date, out_dir)
    doc.insert(top, summary_block(study))
    figs.finish()
    return doc


def _command(config: StageConfig, out_dir: str | Path | None, allow_unbounded: bool) -> str:
    """The command that writes this report again, run where this one was.

    The config as it was named (a bundled stage by its preset name), ``--out`` as
    given (``DIR`` when unknown), ``--allow-unbounded`` when it was needed.
    """
    source = Path(config.source)
    bundled = source.parent in (STAGES_DIR, STAGES_DIR.resolve())
    name = source.stem if bundled else config.source
    out = "DIR" if out_dir is None else shlex.quote(os.fspath(out_dir))
    flags = " --allow-unbounded" if allow_unbounded else ""
    return f"bwdesign report --config {shlex.quote(name)} --out {out}{flags}"


def _mismatch_text(mismatch: dict[str, float]) -> str:
    """``{'a1': 0.02, 'a3': 0.02}`` -> ``a1 +-2 %, a3 +-2 %`` (no Python repr in the report)."""
    return ", ".join(f"{k} +-{100 * float(v):g} %" for k, v in mismatch.items())


def _pole_text(p: complex) -> str:
    if abs(p.imag) < 1e-9 * max(1.0, abs(p)):
        return f"{p.real:.4g}"
    return f"{p.real:.4g}{p.imag:+.4g}j"


def build_report(
    config: StageConfig,
    out: Path,
    *,
    allow_unbounded: bool = False,
    quiet: bool = False,
    date: str | None = None,
    out_dir: str | Path | None = None,
    cache: StudyCache | None = None,
    workers: int = 1,
) -> tuple[Document, Study]:
    """Compute the study of ``config`` and render it, figures into ``out / "figures"``.

    ``out_dir``: the report's directory as the user named it (``out`` may be a
    staging folder inside it), for the reproducibility command's ``--out``.
    Progress lines (``[report] ...``) go to stderr unless ``quiet``. ``cache``: read
    the study and its figures from the study cache when kept there, and keep them
    (:mod:`bwdesign.study.cache`, :mod:`bwdesign.report.figures`). ``workers``: 2 or
    more computes the study and draws the figures on two processes (the same report).
    """
    s = study(
        config,
        allow_unbounded=allow_unbounded,
        progress=_progress(quiet),
        cache=cache,
        workers=workers,
    )
    kept = kept_figures(cache, s.cache_key)
    figs = FigureWriter(Path(out) / "figures", kept, workers=workers)
    doc = render(s, figs, date=date, out_dir=out_dir)
    if set(figs.written) - set(kept or {}):
        keep_figures(cache, s.cache_key, figs)
    return doc, s


def write_report(
    config: StageConfig,
    out_dir: str | Path,
    *,
    allow_unbounded: bool = False,
    quiet: bool = False,
    date: str | None = None,
    force: bool = False,
    cache: StudyCache | None = None,
    workers: int = 1,
) -> ReportOutcome:
    """Write the report for ``config`` into ``out_dir`` through the safe output layer.

    ``out_dir`` is checked before any work (:func:`bwdesign.output.prepare_directory`):
    it must be new, empty or a report bwdesign wrote before (its manifest);
    the files are computed in a staging directory inside it and moved into
    place at the end, so an error or a kill leaves the previous report whole.

    Parameters
    ----------
    config : StageConfig
        Needs [plant], [sampling], [envelope], [reference] and [controller];
        [observer] gains are optional (without them only synthesised gains).
    out_dir : path
    allow_unbounded : bool
    quiet : bool
        No progress lines on stderr.
    date : str, optional
        Date line (default: now, UTC).
    force : bool
        Write into a directory that holds files bwdesign did not write; they
        are kept, never overwritten.
    cache : StudyCache, optional
        Read the study and its figures from the study cache when this very study
        was kept there, and keep them (never in ``out_dir``); default: no cache.
    workers : int
        2 or more: a second process computes part of the study and draws half the
        figures (Linux; :mod:`bwdesign.study.background`); the report is the same.

    Returns
    -------
    ReportOutcome

    Raises
    ------
    ConfigError
        A section the report needs is missing.
    OutputError
        ``out_dir`` cannot be written safely (checked before any work), or the
        operating system refused a write (the previous report is then intact).
    """
    target = prepare_directory(
        out_dir, command="report", force=force, what="--out", expect=REPORT_FILES
    )
    with target.stage() as stage:
        doc, s = build_report(
            config,
            stage.root,
            allow_unbounded=allow_unbounded,
            quiet=quiet,
            date=date,
            out_dir=out_dir,
            cache=cache,
            workers=workers,
        )
        stage.write_text("certificate.json", dump_json(s.to_dict()) + "\n")
        stage.write_text("report.md", doc.to_markdown())
        stage.write_text("report.html", doc.to_html(stage.root))
    return ReportOutcome(out_dir=Path(out_dir), certified=s.verdict.ok, verdict=s.verdict.text)
