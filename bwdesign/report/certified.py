"""The certified-gains report: one stage configuration in, a report to hand on out.

:func:`write_report` turns a :class:`~bwdesign.model.config.StageConfig` into a
directory holding ``report.md``, a self-contained ``report.html``,
``certificate.json`` and ``figures/*.png``. Everything is computed here from
the configuration; nothing is edited by hand. The directory is written through
:mod:`bwdesign.output.files`: staged inside the target and moved into place at
the end, so an error never leaves a half-written report, and no file bwdesign
did not write is ever touched.

The numbers in ``certificate.json`` come from :func:`certificate_document`,
which the determinism test re-runs and compares with the committed file, and
from the report's own sections (:data:`REPORT_SECTIONS`: the synthesis per
tier, the sweep, the robust certificate), which :func:`build_report` adds.
"""

from __future__ import annotations

import os
import platform
import shlex
import sys
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from ..certify.linear import error_dynamics, hysteresis_bode
from ..certify.results import CertificateReport, SynthesisResult
from ..certify.synthesis import synthesize
from ..certify.tiers import certify
from ..control.analysis import analyze_loop
from ..control.tuning import digital_tuning
from ..errors import ConfigError, InputError
from ..model.config import StageConfig
from ..model.envelope import Envelope
from ..model.params import require_bounded
from ..model.stage_presets import STAGES_DIR
from ..model.summary import plant_summary
from ..observers.gains import check_gains, discrete_gains
from ..output.files import prepare_directory
from ..output.jsonenc import dump_json
from ..sim.sweep import check_samples, sweep_box
from .document import Document
from .document import fmt as _fmt
from .robust import robust_section
from .summary import ReportSummary, summary_block
from .sweep import sweep_section
from .tiers import synthesize_per_tier, tier_synthesis_section
from .tracking import TrackingRun, input_limits, required_input, tracking_runs, tracking_section
from .tracking import limits_text as _limits_text

__all__ = ["ReportOutcome", "certificate_document", "write_report", "DEFAULT_DECAY"]

#: Decay rate (1/s) requested from synthesis when the config has no [synthesis] decay.
DEFAULT_DECAY = 100.0

#: Entries of ``certificate.json`` that :func:`build_report` adds to
#: :func:`certificate_document`'s (each from its own section's module).
REPORT_SECTIONS = ("tier_synthesis", "sweep", "robust")

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


def _require(config: StageConfig, *, allow_unbounded: bool = False) -> tuple[float, Envelope]:
    missing = []
    if config.dt is None:
        missing.append("[sampling] (dt)")
    if config.envelope_spec is None:
        missing.append("[envelope] (udot_max or from_reference)")
    if config.reference is None:
        missing.append("[reference] (the trajectory simulated at the envelope)")
    if config.controller is None:
        missing.append("[controller] (lambda1, lambda2)")
    if missing:
        raise ConfigError(
            f"{config.source or 'config'}: the report needs section(s) {', '.join(missing)}"
        )
    env = config.envelope(allow_unbounded=allow_unbounded)
    return float(config.dt), env


def _synthesis_request(config: StageConfig) -> dict[str, Any]:
    spec = config.synthesis or {}
    return {"decay": spec.get("decay", DEFAULT_DECAY), "pole_radius": spec.get("pole_radius")}


def certificate_document(
    config: StageConfig, *, allow_unbounded: bool = False
) -> tuple[dict[str, Any], CertificateReport | None, SynthesisResult]:
    """The content of ``certificate.json`` and the objects behind it.

    Returns
    -------
    doc : dict
        ``configured`` and ``synthesized`` (each a ``bwdesign certify --json``
        document), ``synthesis`` (the request and its outcome), ``envelope``,
        ``firmware`` (discrete gains at dt, full precision) and ``config``.
    configured : CertificateReport or None
    synthesized : SynthesisResult
    """
    params = config.plant
    require_bounded(params, allow_unbounded)
    dt, env = _require(config, allow_unbounded=allow_unbounded)
    v = env.udot_max
    configured = None
    if config.gains is not None:
        configured = certify(
            params, config.gains, udot_max=v, dt=dt, allow_unbounded=allow_unbounded
        )
    req = _synthesis_request(config)
    synth = synthesize(
        params,
        udot_max=v,
        decay=req["decay"],
        pole_radius=req["pole_radius"],
        dt=dt,
        allow_unbounded=allow_unbounded,
    )
    firmware: dict[str, Any] = {
        "dt": dt,
        "form": "x_post = x_prior + K (z - x_prior[0]); see bwdesign.observers",
    }
    if configured is not None:
        firmware["configured_K"] = [float(k) for k in configured.discrete_gains]
    if synth.discrete_gains is not None:
        firmware["synthesized_K"] = [float(k) for k in synth.discrete_gains]
    sdoc = synth.to_dict()
    doc = {
        "config": {"source": Path(config.source).name, "sha256": config.sha256},
        "envelope": env.to_dict(),
        "configured": None if configured is None else configured.to_dict(),
        "synthesized": None if synth.report is None else synth.report.to_dict(),
        "synthesis": {
            k: sdoc[k]
            for k in (
                "feasible",
                "tier",
                "gains",
                "discrete_gains",
                "decay",
                "pole_radius",
                "binding",
                "reason",
                "max_decay",
                "max_udot",
                "solver",
                "status",
            )
        },
        "firmware": firmware,
        "input": _input_document(config, env, allow_unbounded),
        "units": _units(params),
    }
    return doc, configured, synth


def _units(params: Any) -> dict[str, Any]:
    """The units of the numbers in ``certificate.json`` (from the stage's length/input unit)."""
    iu = params.input_unit
    return {
        "length": params.length_unit,
        "input": iu,
        "udot_max": f"{iu}/s",
        "max_udot": f"{iu}/s",
        "decay": "1/s",
        "decay_rate": "1/s",
        "gains": ["1/s", "1/s^2", "1/s"],
        "dt": "s",
        "pole_radius": "rad/s",
    }


def _input_document(config: StageConfig, env: Envelope, allow_unbounded: bool) -> dict[str, Any]:
    """Input limits, the feedforward input the reference needs, and whether it fits."""
    limits = input_limits(config)
    need = required_input(config, env, allow_unbounded=allow_unbounded)
    within = None
    if limits is not None and need is not None:
        within = bool(limits[0] <= need[0] and need[1] <= limits[1])
    return {
        "limits": None if limits is None else list(limits),
        "feedforward_range": None if need is None else list(need),
        "within_limits": within,
    }


def _gains_text(g: Any) -> str:
    return "(" + ", ".join(f"{float(v):.6g}" for v in g) + ")" if g is not None else "-"


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in (
        "bwdesign",
        "numpy",
        "scipy",
        "cvxpy",
        "clarabel",
        "scs",
        "control",
        "filterpy",
        "matplotlib",
    ):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def _tier_cell(rep: CertificateReport | None, name: str) -> list[str]:
    if rep is None:
        return ["-", "-", "-", "-"]
    try:
        c = rep.tier(name)
    except KeyError:
        return ["-", "-", "-", "-"]
    worst = min((m.limit - m.value for m in c.margins), default=None) if c.holds else None
    env = _fmt(c.max_udot) + (" (search limit)" if c.max_udot_capped else "")
    return [
        "**yes**" if c.holds else "no",
        env,
        _fmt(c.decay_rate),
        _fmt(worst, 3) if worst is not None else "-",
    ]


def _verdict(
    config: StageConfig,
    configured: CertificateReport | None,
    synth: SynthesisResult,
    v: float,
    inp: dict[str, Any],
    runs: list[TrackingRun],
) -> tuple[bool, str]:
    """The sentence at the top and the flag behind the exit code.

    Not certified, infeasible synthesis, or a reference whose feedforward input
    leaves ``[controller] u_min/u_max`` each make the flag False (exit 1).
    """
    iu = config.plant.input_unit
    parts = []
    ok = True
    fits = inp["within_limits"] is not False
    if configured is not None:
        if configured.certified and fits:
            parts.append(
                f"CERTIFIED: the configured gains {_gains_text(config.gains)} hold at "
                f"|u'| <= {v:.4g} {iu}/s (strongest tier: {configured.best})."
            )
        elif configured.certified:
            parts.append(
                f"OBSERVER CERTIFIED, REFERENCE OUT OF INPUT LIMITS: the configured gains "
                f"{_gains_text(config.gains)} hold at |u'| <= {v:.4g} {iu}/s (strongest tier: "
                f"{configured.best})."
            )
        else:
            ok = False
            parts.append(
                f"NOT CERTIFIED: no tier certifies the configured gains "
                f"{_gains_text(config.gains)} at |u'| <= {v:.4g} {iu}/s."
            )
    if configured is None:
        parts.append("No observer gains configured ([observer] gains); synthesis only.")
    if synth.feasible:
        where = "at the same envelope" if configured is not None else f"at |u'| <= {v:.4g} {iu}/s"
        parts.append(
            f"Synthesised gains certified {where}: l = {_gains_text(synth.gains)}, "
            f"{synth.tier} tier, |u'| <= {synth.udot_max:.6g} {iu}/s, decay >= "
            f"{synth.decay:g} 1/s, poles within {synth.pole_radius:.6g} rad/s."
        )
    else:
        ok = False
        parts.append(f"SYNTHESIS INFEASIBLE: {synth.reason}.")
    sat = [r.result.saturated_fraction for r in runs if r.result.settings.get("u_limits")]
    sat_text = (
        f"the simulated loops saturate {100 * min(sat):.3g} to {100 * max(sat):.3g} % of the time"
        if sat
        else ""
    )
    if not fits:
        ok = False
        (lo, hi), (a, b) = inp["limits"], inp["feedforward_range"]
        parts.append(
            ("" if configured is not None and configured.certified else "INPUT OUT OF LIMITS: ")
            + f"The reference needs the feedforward input {a:.4g} .. "
            f"{b:.4g} {iu}, outside the input limits {_fmt(lo)} .. {_fmt(hi)} {iu} "
            f"([controller] u_min/u_max); {sat_text}, so the tracking numbers below are for a "
            "saturated loop and the stage cannot follow this reference. What holds: the "
            "observer certificates, for an applied (clipped) input with |u'| within the "
            "envelope; the envelope itself was derived from the unclipped feedforward."
        )
    elif sat and max(sat) > 0:
        parts.append(f"Input limits {_limits_text(inp['limits'], iu)}: {sat_text}.")
    return ok, " ".join(parts)


def _progress(quiet: bool) -> Callable[[str], None]:
    def say(msg: str) -> None:
        if not quiet:
            print(f"[report] {msg}", file=sys.stderr, flush=True)

    return say


def build_report(
    config: StageConfig,
    out: Path,
    *,
    allow_unbounded: bool = False,
    quiet: bool = False,
    date: str | None = None,
    out_dir: str | Path | None = None,
) -> tuple[Document, dict[str, Any], bool, str]:
    """Compute everything and write figures into ``out / "figures"``.

    ``out_dir``: the report's directory as the user named it (``out`` may be a
    staging folder inside it), for the reproducibility command's ``--out``.

    Returns the document, the certificate JSON document, the verdict flag and sentence.
    """
    from ..plotting import figures as plotting

    say = _progress(quiet)
    params = config.plant
    lu, iu = params.length_unit, params.input_unit
    # every check that can end in an `error:` line comes before the first progress line
    require_bounded(params, allow_unbounded)
    dt, env = _require(config, allow_unbounded=allow_unbounded)
    if config.gains is not None:
        check_gains(params, config.gains)
    if config.sweep is not None:
        sweep_box(config)  # [sweep] needs a usable [uncertainty] box: say so now
        try:
            check_samples(config.sweep["samples"], len(config.sweep["observers"]))
        except InputError as err:
            raise ConfigError(f"{config.source or 'config'}: [sweep] samples: {err}") from None
    figs = out / "figures"
    figs.mkdir(parents=True, exist_ok=True)

    say("certifying the configured gains and synthesising a certified set")
    cert_doc, configured, synth = certificate_document(config, allow_unbounded=allow_unbounded)
    v = env.udot_max
    g_loop = config.gains if config.gains is not None else synth.gains
    tuning = digital_tuning(params, dt)
    say("simulating the tracking loop at the envelope (PHSO, ESO and PHDO)")
    runs = tracking_runs(config, gains=g_loop, tuning=tuning, allow_unbounded=allow_unbounded)
    ok, verdict = _verdict(config, configured, synth, v, cert_doc["input"], runs)

    doc = Document(f"Certified-gains report: {params.name or Path(config.source).stem}")
    doc.verdict(verdict, ok)
    top = len(doc.blocks)  # the summary goes here once every section is computed
    doc.para(
        f"Generated by `bwdesign report` from `{Path(config.source).name}`; do not edit. "
        "Every number below is computed from that file."
    )

    # -- plant ---------------------------------------------------------------
    summ = plant_summary(params)
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
    d = summ["derived"]
    rows += [
        ["natural frequency sqrt(a1)/(2 pi)", f"{d['natural_frequency_hz']:.6g}", "Hz"],
        ["damping ratio a2/(2 sqrt(a1))", f"{d['damping_ratio']:.4g}", "-"],
        ["static gain a3/a1", f"{d['static_gain']:.6g}", d["static_gain_unit"]],
    ]
    doc.table(["quantity", "value", "unit"], rows)
    bc = summ["bounded_class"]
    doc.para(f"Bounded class: **{'yes' if bc['bounded'] else 'no'}**. {bc['reason']}.")
    if "note" in summ:
        doc.para(summ["note"])

    # -- envelope ------------------------------------------------------------
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
    inp = cert_doc["input"]
    need = inp["feedforward_range"]
    erows += [
        [
            "feedforward input range (exact inverse)",
            "-" if need is None else f"{need[0]:.4g} .. {need[1]:.4g} {iu}",
        ],
        ["input limits ([controller] u_min, u_max)", _limits_text(inp["limits"], iu)],
        [
            "feedforward within the limits",
            "-" if inp["within_limits"] is None else _fmt(inp["within_limits"]),
        ],
    ]
    doc.table(["item", "value"], erows)
    doc.para(
        f"How: {env.method}. Per sample the certificates bound the input jump by "
        f"|u'| dt = {v * dt:.4g} {iu}."
    )

    # -- certificates ----------------------------------------------------------
    doc.heading("Certificates")
    req = _synthesis_request(config)
    c_decay = 0.0 if configured is None else configured.decay
    s_decay = synth.report.decay if synth.report is not None else req["decay"]
    doc.para(
        f"Configured gains l = {_gains_text(config.gains)}; synthesised gains "
        f"l = {_gains_text(synth.gains)} (discrete K = {_gains_text(synth.discrete_gains)}), "
        f"from an LMI synthesis for the {synth.tier} tier asking decay >= {req['decay']:g} 1/s"
        f" within pole radius {synth.pole_radius:.5g} rad/s. Envelope = the largest |u'| "
        f"({iu}/s) the tier certifies for those gains with at least the decay named in the "
        "column head; decay = certified exponential rate (1/s) at the envelope above; "
        "check = the smallest slack of the eigenvalue checks made outside the solver "
        "(scaled, > 0 passes). The two sets are certified at different required decays "
        f"(configured: >= {c_decay:g} 1/s; synthesised: >= {s_decay:g} 1/s, the synthesis "
        "request), so their envelopes answer different questions: a larger required decay "
        "certifies a smaller envelope."
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

    # -- synthesis per tier ----------------------------------------------------
    say("synthesis per tier (the largest envelope synthesised gains reach)")
    per_tier = synthesize_per_tier(
        params,
        udot_max=v,
        decay=req["decay"],
        dt=dt,
        pole_radius=req["pole_radius"],
        allow_unbounded=allow_unbounded,
    )
    cert_doc["tier_synthesis"] = tier_synthesis_section(doc, params, per_tier, v)

    # -- linear analysis -----------------------------------------------------
    say("linear analysis of the observer error dynamics")
    doc.heading("Observer error dynamics")
    sets = {}
    if config.gains is not None:
        sets["configured"] = config.gains
    if synth.gains is not None:
        sets["synthesised"] = synth.gains
    prow = []
    poles_by_label = {}
    bodes = {}
    for label, g in sets.items():
        ed = error_dynamics(params, g, udot_max=v)
        for k, p, z in zip(ed.k_interval, ed.poles, ed.damping, strict=True):
            prow.append(
                [
                    label,
                    f"{k:.4g}",
                    ", ".join(_pole_text(x) for x in p),
                    ", ".join(f"{x:.3f}" for x in z),
                ]
            )
            poles_by_label[f"{label}, k = {k:.3g}"] = p
        bodes[label] = hysteresis_bode(params, g)
    doc.table(["gains", "k (1/s)", "poles of A - k e3 e3' (1/s)", "damping"], prow)
    fig, _ = plotting.plot_error_poles(poles_by_label, title="observer error poles")
    plotting.save_figure(fig, figs / "error_poles.png")
    doc.figure("figures/error_poles.png", "Observer error poles at both ends of the sector")
    fig, _ = plotting.plot_hysteresis_bode(
        bodes, lipschitz_coeff=abs(params.beta) + abs(params.gamma), udot_max=v, input_unit=iu
    )
    plotting.save_figure(fig, figs / "hysteresis_bode.png")
    doc.figure(
        "figures/hysteresis_bode.png",
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
        f">= {s_decay:g} 1/s, which certifies a smaller envelope."
    )

    # -- tracking loop -------------------------------------------------------
    say("tracking-loop analysis (continuous, sampled, digital tuning)")
    ctl = config.controller
    doc.heading("Tracking loop")
    cont = analyze_loop(params, ctl.lambda1, ctl.lambda2, g_loop)
    samp = analyze_loop(params, ctl.lambda1, ctl.lambda2, g_loop, dt=dt)
    lrow = []
    for label, a in (
        ("eq. 12, continuous", cont),
        ("eq. 12, sampled at dt", samp),
        ("digital tuning (discrete form), sampled", tuning.nominal),
    ):
        lrow.append(
            [
                label,
                _fmt(a.stable),
                _fmt(a.max_real_part),
                _fmt(a.spectral_radius, 8) if a.spectral_radius is not None else "-",
                _fmt(a.gain_margin_db, 3),
                _fmt(a.phase_margin, 3),
                _fmt(a.delay_margin * 1e3, 3),
            ]
        )
    doc.para(
        f"Configured constants lambda1 = {ctl.lambda1:g}, lambda2 = {ctl.lambda2:g} "
        f"with observer gains {_gains_text(g_loop)}; the digital tuning chooses "
        f"lambda1 = {tuning.lambda1:.4g}, lambda2 = {tuning.lambda2:.4g}, integral rate "
        f"{_fmt(tuning.integral_rate)} 1/s and observer gains "
        f"{_gains_text(tuning.gains)} for dt = {dt * 1e3:g} ms."
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
    fig, _ = plotting.plot_loop_poles(
        {"eq. 12 sampled": samp, "digital tuning": tuning.nominal},
        title="tracking loop poles (z-plane)",
    )
    plotting.save_figure(fig, figs / "loop_poles.png")
    doc.figure("figures/loop_poles.png", "Closed-loop poles of the sampled tracking loops")

    # -- simulation ----------------------------------------------------------
    tracking_section(doc, config, runs, figs)
    if config.sweep is not None:
        say(f"Monte Carlo sweep over [uncertainty]: {config.sweep['samples']} scenarios")
        cert_doc["sweep"] = sweep_section(doc, config, figs)
    if config.uncertainty is not None and not config.uncertainty.undetermined():
        say("robust certificate over [uncertainty] (every corner)")
        cert_doc["robust"] = robust_section(doc, config, tuning, v)

    # -- firmware ------------------------------------------------------------
    doc.heading("Gains for firmware")
    fw = cert_doc["firmware"]
    lines = [f"# discrete observer gains at dt = {dt!r} s: x_post = x_prior + K*(z - x_prior[0])"]
    if "configured_K" in fw:
        lines.append(f"K_configured  = {fw['configured_K']!r}")
    if "synthesized_K" in fw:
        lines.append(f"K_synthesised = {fw['synthesized_K']!r}")
    if config.gains is not None:
        K = discrete_gains(params, config.gains, dt)
        lines.append(f"# check: pole matching of l = {list(config.gains)!r} gives {K.tolist()!r}")
    doc.pre("\n".join(lines))

    # -- reproducibility -----------------------------------------------------
    doc.heading("Reproducibility")
    ver = _versions()
    doc.table(
        ["item", "value"],
        [[k, v_] for k, v_ in ver.items()]
        + [
            ["solvers", "Clarabel (fallback SCS); only OPTIMAL is accepted"],
            ["config", Path(config.source).name],
            ["config sha256", config.sha256],
            ["command", _command(config, out_dir, allow_unbounded)],
        ],
    )
    doc.para(f"Date: {date or datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}")
    summary = ReportSummary(
        config, ok, configured, synth, env, runs, tuning, inp, cert_doc.get("robust")
    )
    doc.insert(top, summary_block(summary))
    return doc, cert_doc, ok, verdict


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


def write_report(
    config: StageConfig,
    out_dir: str | Path,
    *,
    allow_unbounded: bool = False,
    quiet: bool = False,
    date: str | None = None,
    force: bool = False,
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
        doc, cert_doc, ok, verdict = build_report(
            config,
            stage.root,
            allow_unbounded=allow_unbounded,
            quiet=quiet,
            date=date,
            out_dir=out_dir,
        )
        stage.write_text("certificate.json", dump_json(cert_doc) + "\n")
        stage.write_text("report.md", doc.to_markdown())
        stage.write_text("report.html", doc.to_html(stage.root))
    return ReportOutcome(out_dir=Path(out_dir), certified=ok, verdict=verdict)
