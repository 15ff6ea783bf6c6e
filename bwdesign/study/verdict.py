"""The study's verdict (the report's first sentence and its exit code) and recommended loop."""

from __future__ import annotations

from collections.abc import Sequence

from ..certify.results import CertificateReport, SynthesisResult
from ..design.tuning import DigitalTuning
from ..model.config import StageConfig
from ..output.text import fmt, gains_text, limits_text
from .result import InputRange, Recommendation, Verdict
from .tracking import TrackingRun

__all__ = ["verdict", "recommend"]


def verdict(
    config: StageConfig,
    configured: CertificateReport | None,
    synth: SynthesisResult,
    udot_max: float,
    inp: InputRange,
    runs: Sequence[TrackingRun],
) -> Verdict:
    """The sentence at the top of the report and the flag behind the exit code.

    Not certified, infeasible synthesis, or a reference whose feedforward input
    leaves ``[controller] u_min/u_max`` each make the flag False (exit 1).
    """
    v, iu = udot_max, config.plant.input_unit
    parts = []
    ok = True
    fits = inp.within_limits is not False
    if configured is not None:
        if configured.certified and fits:
            parts.append(
                f"CERTIFIED: the configured gains {gains_text(config.gains)} hold at "
                f"|u'| <= {v:.4g} {iu}/s (strongest tier: {configured.best})."
            )
        elif configured.certified:
            parts.append(
                f"OBSERVER CERTIFIED, REFERENCE OUT OF INPUT LIMITS: the configured gains "
                f"{gains_text(config.gains)} hold at |u'| <= {v:.4g} {iu}/s (strongest tier: "
                f"{configured.best})."
            )
        else:
            ok = False
            parts.append(
                f"NOT CERTIFIED: no tier certifies the configured gains "
                f"{gains_text(config.gains)} at |u'| <= {v:.4g} {iu}/s."
            )
    if configured is None:
        parts.append("No observer gains configured ([observer] gains); synthesis only.")
    if synth.feasible:
        where = "at the same envelope" if configured is not None else f"at |u'| <= {v:.4g} {iu}/s"
        parts.append(
            f"Synthesised gains certified {where}: l = {gains_text(synth.gains)}, "
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
        (lo, hi), (a, b) = inp.limits, inp.feedforward
        parts.append(
            ("" if configured is not None and configured.certified else "INPUT OUT OF LIMITS: ")
            + f"The reference needs the feedforward input {a:.4g} .. "
            f"{b:.4g} {iu}, outside the input limits {fmt(lo)} .. {fmt(hi)} {iu} "
            f"([controller] u_min/u_max); {sat_text}, so the tracking numbers below are for a "
            "saturated loop and the stage cannot follow this reference. What holds: the "
            "observer certificates, for an applied (clipped) input with |u'| within the "
            "envelope; the envelope itself was derived from the unclipped feedforward."
        )
    elif sat and max(sat) > 0:
        parts.append(f"Input limits {limits_text(inp.limits, iu)}: {sat_text}.")
    return Verdict(ok=ok, text=" ".join(parts))


def recommend(tuning: DigitalTuning, runs: Sequence[TrackingRun]) -> Recommendation:
    """The loop the summary recommends, with its PHSO run.

    The digital tuning (the law tuned for the sample time, with worst-case margins
    checked over its model mismatch) when its requirements are met and its PHSO run
    stays bounded, else eq. 12 with the configured constants when that run stays
    bounded; always with the PHSO, the observer the certificates are about and the
    one ``bwdesign export-c`` exports by default.
    """
    phso = {r.label: r for r in runs if r.label.startswith("PHSO")}
    digital, eq12 = phso.get("PHSO (digital tuning)"), phso.get("PHSO (eq. 12)")
    if tuning.met and digital is not None and digital.result.metrics is not None:
        return Recommendation("digital tuning", digital)
    if eq12 is not None and eq12.result.metrics is not None:
        return Recommendation("eq. 12", eq12)
    return Recommendation(None, None)
