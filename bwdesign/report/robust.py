"""The certified-gains report's robust section: certificates over ``[uncertainty]``.

For the digital tuning's loop (its eq. (12) constants, integral rate and
compensated delay) with the PHSO and with the disturbance observer (PHDO, the
tuning's ``(l1, l2, 0, l3)``): :func:`bwdesign.certify_robust` over every corner
of the box, beside the worst error :func:`bwdesign.sim.simulate_batch` finds at
those corners. Like for like, the simulated columns are steady-state max
``|error|`` (tracking, ``x1`` and ``x3`` estimates; the PHDO's ``x3`` is the
lumped ``x3hat + dhat``) over the batch's metrics window (the last two reference
periods), as the certified bounds are peak bounds after the transient.

A robust certificate assumes the loop keeps ``|u'| <= udot_max`` and does not
prove it: the corners are simulated first, and when their input moves faster than
the stage's envelope the certificate is asked for
:func:`bwdesign.sim.robust_design.certified_envelope` of their fastest rate, and
the report says so.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..certify.robust import certify_robust
from ..control.loop import ClosedLoop
from ..model.config import StageConfig
from ..sim.robust_design import certified_envelope, simulate_corners

__all__ = ["robust_section"]

_OBSERVERS = {"phso": "PHSO", "phdo": "PHDO (lumped x3hat + dhat)"}


def _loop(config: StageConfig, tuning: Any, udot_max: float, observer: str) -> dict[str, Any]:
    params, box, ref, dt = config.plant, config.uncertainty, config.reference, float(config.dt)
    gains = tuning.observer_gains_for(observer)
    loop = ClosedLoop.from_config(config, observer=observer, law=tuning, saturate=False)
    sim = simulate_corners(loop, box, ref)
    stable = bool(sim.stable.all())
    rate = float(np.nanmax(sim.input_rate_max)) if stable else math.nan
    env = certified_envelope(udot_max, rate) if stable else udot_max
    rc = certify_robust(
        params,
        gains,
        dt=dt,
        uncertainty=box,
        udot_max=env,
        reference=ref,
        lambda1=tuning.lambda1,
        lambda2=tuning.lambda2,
        integral_rate=tuning.integral_rate,
        delay=tuning.delay,
        observer=observer,
    )
    worst = float(np.nanmax(sim.maxe)) if stable else math.nan
    worst_est = np.nanmax(sim.estimation_maxe, axis=0) if stable else np.full(3, math.nan)
    ratio = rc.tracking_bound / worst if rc.holds and worst > 0 else None
    return {
        "observer": observer,
        "gains": list(gains),
        "certificate": rc,
        "envelope": env,
        "simulated_input_rate_max": rate,
        "simulated_worst_maxe": worst,
        "simulated_worst_estimation_maxe": worst_est.tolist(),
        "simulated_window": list(sim.window),
        "samples": sim.samples,
        "all_corners_stable": stable,
        "conservatism": ratio,
    }


def robust_section(doc: Any, config: StageConfig, tuning: Any, udot_max: float) -> dict[str, Any]:
    """Add the robust-certificate section to ``doc``; return its ``certificate.json`` entry.

    The certified bounds are noise free (``noise_max = 0``) and so is the vertex
    simulation, so the columns compare the same loops.
    """
    params, box, ref, dt = config.plant, config.uncertainty, config.reference, float(config.dt)
    lu, iu = params.length_unit, params.input_unit
    loops = [_loop(config, tuning, udot_max, obs) for obs in _OBSERVERS]
    doc.heading("Robust certificate over the uncertainty box")
    widths = box.describe(params)
    n_corners = loops[0]["certificate"].n_vertices
    doc.para(
        f"Box: {widths} ({n_corners} corners). Loop: the digital tuning (observer gains "
        f"{', '.join(f'{g:.6g}' for g in tuning.gains)}; the PHDO gets (l1, l2, 0, l3); "
        f"lambda = {tuning.lambda1:.4g} 1/s, integral rate {tuning.integral_rate} 1/s, delay "
        f"{'on' if tuning.delay else 'off'}) at dt = {dt:g} s, no sensor noise. One quadratic "
        "Lyapunov function for every corner and both ends of the hysteresis jump-map slope; "
        "the model error enters as an input driven by the state and the reference, its slow "
        "part through its increments (bwdesign.certify.robust). The certificate assumes the "
        f"loop keeps an input-rate envelope: the stage's |u'| <= {udot_max:.4g} {iu}/s, or "
        "1.1 x the fastest input rate simulated at the corners when that is faster."
    )
    for lp in loops:
        rc = lp["certificate"]
        name = _OBSERVERS[lp["observer"]]
        raised = lp["envelope"] > udot_max
        doc.para(
            f"{name}: the corners' input reaches {lp['simulated_input_rate_max']:.4g} {iu}/s"
            + (
                f", above the stage's envelope: certified for |u'| <= {lp['envelope']:.4g} "
                f"{iu}/s instead"
                if raised
                else f", within the stage's envelope |u'| <= {udot_max:.4g} {iu}/s"
            )
            + ". Verdict: "
            + rc.status
            + "."
        )

    def cell(x: float | None) -> str:
        return "—" if x is None or not math.isfinite(x) else f"{x:.4g}"

    rows = []
    for lp in loops:
        rc, est = lp["certificate"], lp["simulated_worst_estimation_maxe"]
        name = lp["observer"].upper()
        for what, b, w in (
            (f"max |x1 - x_d| ({lu})", rc.tracking_bound, lp["simulated_worst_maxe"]),
            (f"max |x1hat - x1| ({lu})", rc.estimation_bound, est[0]),
            (f"max |x3hat - x3| ({lu})", rc.x3_estimation_bound, est[2]),
        ):
            ratio = b / w if rc.holds and b is not None and w > 0 else None
            rows.append([name, what, cell(b), cell(w), cell(ratio)])
    w0, w1 = loops[0]["simulated_window"]
    doc.para(
        "Both columns are peak (max) errors in steady state: the certified bound holds after "
        "the transient; the simulated column is the largest |error| at any corner over "
        + ("the last two reference periods" if ref.period else "the last half of the run")
        + f" ({w0:g} .. {w1:g} s of {loops[0]['samples'] * dt:g} s, from the reference's "
        "initial state)."
    )
    doc.table(
        [
            "observer",
            "steady error",
            "certified bound",
            "worst simulated at the corners",
            "certified / simulated",
        ],
        rows,
    )
    ratios = [
        f"{lp['observer'].upper()} {lp['conservatism']:.3g}" for lp in loops if lp["conservatism"]
    ]
    if ratios:
        doc.para(
            "Conservatism (certified / simulated tracking error): " + ", ".join(ratios) + ". "
            "`bwdesign synthesize --plant FILE --robust` searches gains and laws against the "
            "box for the smallest certified bound."
        )
    return {
        "observers": {
            lp["observer"]: {**lp, "certificate": lp["certificate"].to_dict()} for lp in loops
        },
    }
