"""The summary block at the top of the certified-gains report.

Four rows a person reads first: the verdict, the envelope, the tracking error
of the recommended loop and what to export. Every number in them is one of the
study's (the certificates, the envelope, the tracking runs, the digital tuning,
the robust section); nothing is computed here. The recommended loop is the
study's :attr:`~bwdesign.study.Study.recommendation`
(:func:`bwdesign.study.verdict.recommend`).
"""

from __future__ import annotations

import math
from pathlib import Path

from ..output.text import gains_text
from ..study import Study
from .document import Document, fmt

__all__ = ["summary_block"]


def _verdict_row(s: Study) -> str:
    c, synth = s.configured, s.synthesis.result
    head = "**CERTIFIED**" if s.verdict.ok else "**NOT CERTIFIED**"
    if c is not None and c.certified:
        why = f"the configured gains {gains_text(s.config.gains)} (strongest tier: {c.best})"
    elif c is not None:
        why = f"no tier certifies the configured gains {gains_text(s.config.gains)}"
    elif synth.feasible:
        why = (
            f"no gains configured; the synthesised gains {gains_text(synth.gains)} "
            f"({synth.tier} tier)"
        )
    else:
        why = "no gains configured"
    if not synth.feasible:
        why += "; synthesis infeasible"
    if s.input.within_limits is False:
        why += "; the reference's feedforward input leaves the input limits"
    return f"{head}: {why}"


def _envelope_row(s: Study) -> str:
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


def _tracking_row(s: Study) -> str:
    law, run = s.recommendation.law, s.recommendation.run
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
        (r for r in s.tracking if r.label.startswith("PHSO") and r is not run),
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
    nominal = () if s.robust is None else s.robust.nominal
    nom = next((lp.certificate for lp in nominal if lp.observer == "phso"), None)
    if law == "digital tuning" and nom is not None and nom.holds:
        text += (
            f"; certified for the nominal plant: steady max |x1 - x_d| <= "
            f"{fmt(nom.tracking_bound, 3)} {lu}"
        )
    rob = None if s.robust is None else s.robust.loop("phso")
    if law == "digital tuning" and rob is not None:
        cert = rob.certificate
        if cert.holds and cert.tracking_bound is not None:
            text += (
                f"; certified over the [uncertainty] box: steady max |x1 - x_d| <= "
                f"{fmt(cert.tracking_bound, 3)} {lu}"
            )
        else:
            text += "; not certified over the [uncertainty] box (see the robust section)"
    return text


def _export_row(s: Study) -> str:
    law = s.recommendation.law
    name = Path(s.config.source).name
    cmd = f"bwdesign export-c --config {name} --out fw"
    iu, v = s.config.plant.input_unit, s.envelope.udot_max
    c, synth = s.configured, s.synthesis.result
    synth_text = (
        f"`{cmd} --synthesize`: the synthesised gains {gains_text(synth.gains)}, certified at "
        f"|u'| <= {v:.4g} {iu}/s, discrete K = {gains_text(synth.discrete_gains)}"
        if synth.feasible
        else ""
    )
    if not s.verdict.ok:
        if s.input.within_limits is False:
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
            f"{gains_text(t.gains)} and constants lambda1 = {t.lambda1:.4g}, lambda2 = "
            f"{t.lambda2:.4g}, integral rate {fmt(t.integral_rate)} 1/s; export-c writes "
            f"them only when a tier certifies those gains at |u'| <= {v:.4g} {iu}/s (exit 1 "
            "otherwise)"
        )
    if c is not None:
        return f"`{cmd}`: the configured gains, discrete K = {gains_text(c.discrete_gains)}"
    return synth_text


def summary_block(study: Study) -> Document:
    """The summary as a document of its own, for :meth:`Document.insert` at the top."""
    doc = Document("")
    doc.summary(
        [
            ["verdict", _verdict_row(study)],
            ["envelope", _envelope_row(study)],
            ["tracking (recommended loop)", _tracking_row(study)],
            ["export", _export_row(study)],
        ]
    )
    return doc
