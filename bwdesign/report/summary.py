"""The summary block at the top of the certified-gains report.

Four rows a person reads first: the verdict, the envelope, the tracking error
of the recommended loop and what to export. Every number in them is one the
report computed for its sections (the certificates, the envelope, the tracking
runs, the digital tuning, the robust section); nothing is recomputed here.

The recommended loop is the digital tuning (the law tuned for the sample time,
with worst-case margins checked over its model mismatch) when its requirements
are met and its PHSO run stays bounded, else eq. 12 with the configured
constants; always with the PHSO, the observer the certificates are about and
the one ``bwdesign export-c`` exports by default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .document import Document, fmt

__all__ = ["ReportSummary", "summary_block"]


@dataclass(frozen=True)
class ReportSummary:
    """What the summary block is built from (all of it computed by the report).

    Attributes
    ----------
    config : StageConfig
    ok : bool
        The report's verdict flag (its exit code).
    configured : CertificateReport or None
    synth : SynthesisResult
    envelope : Envelope
    runs : list of TrackingRun
    tuning : DigitalTuning
    input_doc : dict
        ``certificate.json``'s ``input`` entry (``within_limits``).
    robust : dict or None
        ``certificate.json``'s ``robust`` entry, when the report has that section.
    """

    config: Any
    ok: bool
    configured: Any
    synth: Any
    envelope: Any
    runs: list
    tuning: Any
    input_doc: dict
    robust: dict | None = None


def _gains(g: Any) -> str:
    return "(" + ", ".join(f"{float(v):.6g}" for v in g) + ")"


def _verdict_row(s: ReportSummary) -> str:
    c, synth = s.configured, s.synth
    head = "**CERTIFIED**" if s.ok else "**NOT CERTIFIED**"
    if c is not None and c.certified:
        why = f"the configured gains {_gains(s.config.gains)} (strongest tier: {c.best})"
    elif c is not None:
        why = f"no tier certifies the configured gains {_gains(s.config.gains)}"
    elif synth.feasible:
        why = (
            f"no gains configured; the synthesised gains {_gains(synth.gains)} ({synth.tier} tier)"
        )
    else:
        why = "no gains configured"
    if not synth.feasible:
        why += "; synthesis infeasible"
    if s.input_doc.get("within_limits") is False:
        why += "; the reference's feedforward input leaves the input limits"
    return f"{head}: {why}"


def _envelope_row(s: ReportSummary) -> str:
    env, iu = s.envelope, s.config.plant.input_unit
    dt = float(s.config.dt)
    if env.source == "reference" and env.derived is not None:
        how = f"from the reference: {env.derived:.4g} {iu}/s x margin {env.margin:g}"
    else:
        how = env.method or env.source
    text = f"|u'| <= {env.udot_max:.4g} {iu}/s ({how}), dt = {dt * 1e3:g} ms"
    c = s.configured
    if c is not None and c.certified:
        t = c.tier(c.best)
        if math.isinf(t.max_udot):
            text += f"; the configured gains hold at every |u'| ({c.best} tier)"
        else:
            cap = " (the search limit)" if t.max_udot_capped else ""
            text += (
                f"; the configured gains hold up to {fmt(t.max_udot)}{cap} {iu}/s ({c.best} tier)"
            )
    return text


def _recommended(s: ReportSummary) -> tuple[str | None, Any]:
    """(law, PHSO run) of the recommended loop, or (None, None)."""
    phso = {r.label: r for r in s.runs if r.label.startswith("PHSO")}
    digital, eq12 = phso.get("PHSO (digital tuning)"), phso.get("PHSO (eq. 12)")
    if s.tuning.met and digital is not None and digital.result.metrics is not None:
        return "digital tuning", digital
    if eq12 is not None and eq12.result.metrics is not None:
        return "eq. 12", eq12
    return None, None


def _tracking_row(s: ReportSummary, law: str | None, run: Any) -> str:
    lu = s.config.plant.length_unit
    if run is None:
        return "no loop stays bounded in the simulation (see Simulated tracking)"
    m, (w0, w1) = run.result.metrics, run.result.window
    if law == "digital tuning":
        why = (
            f"the digital tuning (tuned for dt; worst-case margins met over "
            f"{', '.join(f'{k} +-{100 * float(v):g} %' for k, v in s.tuning.mismatch.items())})"
        )
    else:
        why = "eq. 12 with the configured constants (the digital tuning's " + (
            "run does not stay bounded)" if s.tuning.met else "margin requirements are not met)"
        )
    text = (
        f"{why} with the PHSO: MAXE {fmt(m.maxe, 3)} {lu}, RMSE {fmt(m.rmse, 3)} {lu} "
        f"over {w0:.3g} .. {w1:.3g} s, nominal plant"
    )
    other = next(
        (r for r in s.runs if r.label.startswith("PHSO") and r is not run),
        None,
    )
    if other is not None:
        what = (
            f"MAXE {fmt(other.result.metrics.maxe, 3)} {lu}"
            if other.result.metrics is not None
            else "diverges"
        )
        name = "eq. 12 with the configured constants" if law != "eq. 12" else "digital tuning"
        text += f" ({name}: {what})"
    rob = (s.robust or {}).get("observers", {}).get("phso")
    if law == "digital tuning" and rob is not None:
        cert = rob["certificate"]
        if cert["holds"] and cert["tracking_bound"] is not None:
            text += (
                f"; certified over the [uncertainty] box: steady max |x1 - x_d| <= "
                f"{fmt(cert['tracking_bound'], 3)} {lu}"
            )
        else:
            text += "; not certified over the [uncertainty] box (see the robust section)"
    return text


def _export_row(s: ReportSummary, law: str | None) -> str:
    name = Path(s.config.source).name
    cmd = f"bwdesign export-c --config {name} --out fw"
    iu, v = s.config.plant.input_unit, s.envelope.udot_max
    c, synth = s.configured, s.synth
    synth_text = (
        f"`{cmd} --synthesize`: the synthesised gains {_gains(synth.gains)}, certified at "
        f"|u'| <= {v:.4g} {iu}/s, discrete K = {_gains(synth.discrete_gains)}"
        if synth.feasible
        else ""
    )
    if not s.ok:
        if s.input_doc.get("within_limits") is False:
            return (
                "nothing yet: the reference needs more input than [controller] u_min/u_max "
                "allow; change the reference or the limits first"
            )
        if c is not None and not c.certified and synth.feasible:
            return f"not the configured gains (no tier certifies them); {synth_text}"
        return "nothing: no certified gains (export-c refuses uncertified gains)"
    if law == "digital tuning":
        t = s.tuning
        return (
            f"`{cmd} --tuning digital`: the digital tuning's observer gains "
            f"{_gains(t.gains)} and constants lambda1 = {t.lambda1:.4g}, lambda2 = "
            f"{t.lambda2:.4g}, integral rate {fmt(t.integral_rate)} 1/s; export-c writes "
            f"them only when a tier certifies those gains at |u'| <= {v:.4g} {iu}/s (exit 1 "
            "otherwise)"
        )
    if c is not None:
        return f"`{cmd}`: the configured gains, discrete K = {_gains(c.discrete_gains)}"
    return synth_text


def summary_block(summary: ReportSummary) -> Document:
    """The summary as a document of its own, for :meth:`Document.insert` at the top."""
    law, run = _recommended(summary)
    doc = Document("")
    doc.summary(
        [
            ["verdict", _verdict_row(summary)],
            ["envelope", _envelope_row(summary)],
            ["tracking (recommended loop)", _tracking_row(summary, law, run)],
            ["export", _export_row(summary, law)],
        ]
    )
    return doc
