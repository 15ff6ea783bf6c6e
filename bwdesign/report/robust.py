"""The certified-gains report's robust section, rendered from :attr:`Study.robust`.

The certificates over ``[uncertainty]`` and the corners simulated beside them are
computed by :mod:`bwdesign.study.robust`.
"""

from __future__ import annotations

import math

from ..design.robust import certified_envelope
from ..study import Study
from .document import Document

__all__ = ["robust_section"]

_OBSERVERS = {"phso": "PHSO", "phdo": "PHDO (lumped x3hat + dhat)"}


def robust_section(doc: Document, study: Study) -> None:
    """Add the robust-certificate section (:attr:`Study.robust`) to ``doc``.

    The certified bounds are noise free (``noise_max = 0``) and so is the vertex
    simulation, so the columns compare the same loops.
    """
    config, tuning, part = study.config, study.tuning, study.robust
    params, ref, dt = config.plant, config.reference, float(config.dt)
    lu, iu = params.length_unit, params.input_unit
    loops, bounds, udot_max = part.loops, part.bounds, part.udot_max
    if not loops:
        _nominal_section(doc, study)
        return
    doc.heading("Robust certificate over the uncertainty box")
    widths = ", ".join(f"{k} in [{lo:.6g}, {hi:.6g}]" for k, (lo, hi) in bounds.items() if lo != hi)
    n_corners = loops[0].certificate.n_vertices
    doc.para(
        f"Box: {widths} ({n_corners} corners). Loop: the digital tuning (observer gains "
        f"{', '.join(f'{g:.6g}' for g in tuning.gains)}; the PHDO gets (l1, l2, 0, l3); "
        f"lambda = {tuning.lambda1:.4g} 1/s, integral rate {tuning.integral_rate} 1/s, delay "
        f"{'on' if tuning.delay else 'off'}) at dt = {dt:g} s, no sensor noise. The model "
        "error enters as an input driven by the state and the reference; the loop's response "
        "to the reference itself is computed exactly at its samples where the reference "
        "allows (bwdesign.certify.response), the rest bounded by one quadratic Lyapunov "
        "function for every corner and both ends of the hysteresis jump-map slope and, per "
        "plant, by peak-to-peak (l1) bounds, the smaller kept (bwdesign.certify.robust). The "
        "certificate assumes the loop keeps an input-rate envelope: the stage's |u'| <= "
        f"{udot_max:.4g} {iu}/s, or 1.1 x the fastest input rate found when that is faster; "
        "and a second-difference envelope, 1.1 x the largest |u_k - 2 u_(k-1) + u_(k-2)| / "
        "dt^2 found, with which the plant's hysteresis jump is bounded where the input turns "
        "(bwdesign.model.plant.hysteresis_jump_bound). Both are assumptions, stated in each "
        "verdict."
    )
    dist = part.disturbance
    if dist is not None:
        f = dist.rate_max / (2 * math.pi * dist.input_max) if dist.input_max > 0 else 0.0
        doc.para(
            f"Assumed beside the box ([uncertainty.disturbance], {dist.source}): an "
            f"input-equivalent disturbance d on the plant with |d| <= {dist.input_max:.4g} "
            f"{iu} and |d'| <= {dist.rate_max:.4g} {iu}/s, certified as a slow input; every "
            f"corner is simulated with d = +-{dist.input_max:.4g} sin(2 pi {f:.4g} Hz t) and "
            f"a ramp at +-{dist.rate_max:.4g} {iu}/s to +-{dist.input_max:.4g} {iu}, held."
        )
    for lp in loops:
        rc = lp.certificate
        name = _OBSERVERS[lp.observer]
        corners = certified_envelope(udot_max, lp.simulated_input_rate_max)
        raised = corners > udot_max
        doc.para(
            f"{name}: the input reaches {lp.simulated_input_rate_max:.4g} {iu}/s"
            + (
                f", above the stage's envelope: certified for |u'| <= {corners:.4g} {iu}/s instead"
                if raised
                else f", within the stage's envelope |u'| <= {udot_max:.4g} {iu}/s"
            )
            + (
                f"; certified at |u'| <= {lp.envelope:.4g} {iu}/s, where the certificate's "
                "own rate bound proves the envelope"
                if lp.envelope > corners
                else ""
            )
            + ". Verdict: "
            + rc.status
            + "."
        )

    rows = _rows(loops, lu) + _rows(part.nominal, lu, " (nominal)")
    w0, w1 = loops[0].simulated_window
    found = loops[0].found
    searched = (
        f"{found.plants} plants (every corner, uniform interior points and a seeded search "
        "around the worst, bwdesign.sim.falsify)"
        if found is not None
        else "every corner"
    )
    doc.para(
        "Both columns are peak (max) errors in steady state: the certified bound (an upper "
        "bound) holds after the transient; the found column (a lower bound of the worst case) "
        f"is the largest |error| the falsifier found over {searched}, over "
        + ("the last two reference periods" if ref.period else "the last half of the run")
        + f" ({w0:g} .. {w1:g} s of {loops[0].samples * dt:g} s, from the reference's "
        "initial state). The nominal rows are the same certificate for the nominal plant "
        "alone (a box of zero width)."
    )
    doc.table(_HEADER, rows)
    ratios = [f"{lp.observer.upper()} {lp.conservatism:.3g}" for lp in loops if lp.conservatism]
    if ratios:
        doc.para(
            "Conservatism (certified / found tracking error): " + ", ".join(ratios) + ". "
            "`bwdesign synthesize --plant FILE --robust` searches gains and laws against the "
            "box for the smallest certified bound."
        )
    _made_of_para(doc, (*loops, *part.nominal))


def _made_of_para(doc: Document, loops) -> None:
    made = [m for lp in loops if (m := _made_of(lp))]
    if made:
        doc.para(
            "What each certified tracking bound is made of (the inputs' parts of the "
            "peak-to-peak bound at the plant attaining it, largest first; "
            "`certificate.json`: `tracking_bound_parts`): " + "; ".join(made) + "."
        )


def _made_of(lp) -> str | None:
    """``"PHSO: hysteresis jump 99.9 %, ..."``: the parts of 1 % or more of the bound."""
    parts = lp.certificate.details.get("tracking_bound_parts") if lp.certificate.holds else None
    total = sum(parts.values()) if parts else 0.0
    if not total > 0:
        return None
    tag = " (nominal)" if lp.certificate.n_vertices == 1 and not lp.certificate.n_interior else ""
    big = sorted(((v / total, k) for k, v in parts.items() if v >= 0.01 * total), reverse=True)
    return f"{lp.observer.upper()}{tag}: " + ", ".join(f"{k} {100 * r:.1f} %" for r, k in big)


_HEADER = ["observer", "steady error", "certified bound", "worst found", "certified / found"]


def _cell(x: float | None) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.4g}"


def _rows(loops, lu: str, tag: str = "") -> list[list[str]]:
    rows = []
    for lp in loops:
        rc, est = lp.certificate, lp.simulated_worst_estimation_maxe
        name = lp.observer.upper() + tag
        for what, b, w in (
            (f"max |x1 - x_d| ({lu})", rc.tracking_bound, lp.simulated_worst_maxe),
            (f"max |x1hat - x1| ({lu})", rc.estimation_bound, est[0]),
            (f"max |x3hat - x3| ({lu})", rc.x3_estimation_bound, est[2]),
        ):
            floor = rc.details.get("rounding_floor")
            if b is not None and floor is not None and b <= floor:  # nothing to compare
                rows.append([name, what, f"≤ {floor:.2g} (rounding)", _cell(w), "—"])
                continue
            ratio = b / w if rc.holds and b is not None and w > 0 else None
            rows.append([name, what, _cell(b), _cell(w), _cell(ratio)])
    return rows


def _nominal_section(doc: Document, study: Study) -> None:
    """A stage without ``[uncertainty]``: the certificate of the nominal loop alone."""
    part, lu = study.robust, study.config.plant.length_unit
    doc.heading("Certificate of the nominal loop")
    doc.para(
        "The robust loop certificate (bwdesign.certify_robust) for the nominal plant alone "
        "(a box of zero width): the digital tuning's loop, no sensor noise, beside the worst "
        "case simulated (bwdesign.sim.falsify). The stage has no [uncertainty] box; add one "
        "for the certificate over the plants it allows."
    )
    for lp in part.nominal:
        doc.para(f"{lp.observer.upper()}: verdict: {lp.certificate.status}.")
    doc.table(_HEADER, _rows(part.nominal, lu, " (nominal)"))
    _made_of_para(doc, part.nominal)
