"""What the Bouc-Wen model does not explain, as numbers: a disturbance bound and its coverage.

**Disturbance.** On every training and validation record the output the Bouc-Wen
part of the chosen fit does not explain, ``e = y - y_BW`` (the fit's parameters,
offset and initial state driven by the commanded input only: the residual plus
the chosen extensions' contribution: amplifier lag, creep, drift), is smoothed by
a centred moving average over :data:`WINDOW_S` (at least :data:`MIN_WINDOW`
samples; the fast remainder is sensor noise) and mapped to the input through the
static gain, ``d = smooth(e) / (a3/a1)`` (a slowly varying input disturbance
reaches the output through the static gain). Then ``input_max = MARGIN max |d|``
and ``rate_max = MARGIN max |d'|`` (central differences of the smoothed ``d``),
over all records, with :data:`MARGIN`, plus the creep a fitted creep candidate
could add at another input (:func:`creep_reserve`).

**Coverage.** On the validation record(s) (offset and initial state re-estimated
with the Bouc-Wen part), else on the last :data:`HOLDOUT` of each training record
(simulated by the fit itself: not independent), the Bouc-Wen output is simulated
at every corner of the ``[uncertainty]`` box (a parameter with an infinite
half-width is held at its nominal value and named), and the band between the
lowest and highest corner, widened by ``|a3/a1| input_max`` (the disturbance
bound's output effect) and by ``3 sigma`` of the sensor noise (the fast remainder
on the training records), is checked against the measured output. ``coverage`` is
the share of held-out samples inside it, with the band widened by the bound *from
the training records alone* (a held-out check: the validation records did not size
it). The bound
written to the stage file is taken over the validation records too; the share
inside the band it gives is in the details (``coverage_full_bound``).
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from ..errors import BWDesignError
from ..model.params import BoucWenParams
from ..model.uncertainty import DisturbanceBound
from .extend import HOLDOUT
from .extstack import creep_response
from .problem import Problem, delayed_input, theta_from_params
from .result import IdentificationResult, validate_record
from .stack import Stack

__all__ = [
    "unexplained",
    "creep_reserve",
    "coverage_note",
    "WINDOW_S",
    "MIN_WINDOW",
    "MARGIN",
    "NOISE_SIGMAS",
    "COVERAGE_TARGET",
]

#: Smoothing window of the disturbance (s).
WINDOW_S = 0.01
#: Least smoothing window (samples).
MIN_WINDOW = 11
#: Margin on the largest disturbance and rate seen.
MARGIN = 1.2
#: Sensor-noise half-width of the coverage band (standard deviations).
NOISE_SIGMAS = 3.0
#: Share of held-out samples the band should contain.
COVERAGE_TARGET = 0.95
_NAMES = ("a1", "a2", "a3", "alpha", "beta", "gamma")


def _window(dt: float) -> int:
    w = max(MIN_WINDOW, int(round(WINDOW_S / dt)))
    return w + 1 - w % 2


def _smooth(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving average over ``w`` samples (shorter at the ends)."""
    if x.size < w:
        w = max(1, x.size - 1 + x.size % 2)
    kernel = np.ones(w)
    return np.convolve(x, kernel, "same") / np.convolve(np.ones_like(x), kernel, "same")


def unexplained(
    result: IdentificationResult,
    theta: np.ndarray,
    records: list,
    valids: list,
    delay: int,
    extensions: dict[str, Any] | None = None,
) -> tuple[DisturbanceBound, float | None, dict[str, Any]]:
    """The disturbance bound, the coverage and how both were computed (module docstring).

    ``extensions``: the selection's document; a fitted creep candidate (chosen or
    not) widens the bound by the creep its weights could add at another input.
    """
    p = result.params
    gain = p.static_gain
    sign = math.copysign(1.0, p.a3)
    base = Stack.build(records, sign, delay=delay)
    errs = [rec.y - m for rec, m in zip(records, base.predict_each(theta), strict=True)]
    held = []  # (problem, fit vector, first held-out sample)
    for rec in valids:
        vprob = Problem(delayed_input(rec.u, delay), rec.y, rec.dt, sign)
        pred, th_v = validate_record(vprob, base.local(theta, 0))
        errs.append(rec.y - pred)
        held.append((vprob, th_v, 0))
    if not valids:
        for k, pk in enumerate(base.problems):
            held.append((pk, base.local(theta, k), int(round((1.0 - HOLDOUT) * pk.y.size))))
    dts = [r.dt for r in records] + [r.dt for r in valids]
    d_max, rate, fast, d_train = 0.0, 0.0, [], 0.0
    for j, (e, dt) in enumerate(zip(errs, dts, strict=True)):
        s = _smooth(e, _window(dt))
        d = s / gain
        d_max = max(d_max, float(np.max(np.abs(d))))
        d_train = d_max if j < len(records) else d_train
        if d.size > 2:
            rate = max(rate, float(np.max(np.abs(np.gradient(d, dt)))))
        fast.append(e - s)
    n_train = len(records)
    noise = float(np.sqrt(np.mean(np.concatenate(fast[:n_train]) ** 2)))
    creep = creep_reserve(extensions, records, delay)
    d_max += creep["input"] / abs(gain)
    rate += creep["rate"] / abs(gain)
    d_train += creep["input"] / abs(gain)
    bound = DisturbanceBound(MARGIN * d_max, MARGIN * rate, source="identified")
    half = abs(gain) * bound.input_max + NOISE_SIGMAS * noise
    outside, nominal_for, n_corners = _outside(result, held)
    cov_full = float(np.mean(outside <= half)) if outside.size else None
    # the bound from the training records alone: the held-out check of its size
    half_train = abs(gain) * MARGIN * d_train + NOISE_SIGMAS * noise
    coverage = float(np.mean(outside <= half_train)) if outside.size else None
    details = {
        "rule": (
            "d = moving average of (y - Bouc-Wen output) / (a3/a1); input_max and rate_max "
            f"= {MARGIN:g} x the largest |d| and |d'| over the training and validation records"
        ),
        "window_s": WINDOW_S,
        "min_window_samples": MIN_WINDOW,
        "margin": MARGIN,
        "static_gain": gain,
        "noise_std": noise,
        "creep_reserve": creep,
        "band": {
            "heldout": (
                "validation record(s)"
                if valids
                else f"last {100 * HOLDOUT:g} % of each training record (not independent)"
            ),
            "corners": n_corners,
            "nominal_for": nominal_for,
            "half_width": half,
            "noise_sigmas": NOISE_SIGMAS,
            "coverage_full_bound": cov_full,
            "input_max_training": MARGIN * d_train,
        },
    }
    return bound, coverage, details


def _corners(result: IdentificationResult) -> tuple[list[BoucWenParams], list[str]]:
    """The box's corner parameter sets (valid ones), and the names held at nominal."""
    p = result.params
    box = result.to_uncertainty()
    nominal_for = [n for n in _NAMES if not math.isfinite(box.half_width(n, p))]
    spans = [
        (n, box.half_width(n, p))
        for n in _NAMES
        if n not in nominal_for and box.half_width(n, p) > 0
    ]
    out = [p]
    for signs in itertools.product((-1.0, 1.0), repeat=len(spans)):
        vals = {n: getattr(p, n) for n in _NAMES}
        for s, (n, hw) in zip(signs, spans, strict=True):
            vals[n] += s * hw
        try:
            out.append(BoucWenParams(**vals))
        except BWDesignError:
            continue  # outside the valid class: not a stage
    return out, nominal_for


def _outside(result: IdentificationResult, held: list) -> tuple[np.ndarray, list[str], int]:
    """Per held-out sample, how far (µm) the measured output lies outside the band
    between the lowest and highest corner output (0 inside)."""
    corners, nominal_for = _corners(result)
    sign = math.copysign(1.0, result.params.a3)
    parts = []
    for prob, th, start in held:
        lo = hi = None
        for c in corners:
            if math.copysign(1.0, c.a3) != sign:
                continue
            th_c = th.copy()
            th_c[:6] = theta_from_params(c)[0][:6]
            pred = prob.predict(th_c)[start:]
            lo = pred if lo is None else np.minimum(lo, pred)
            hi = pred if hi is None else np.maximum(hi, pred)
        y = prob.y[start:]
        parts.append(np.maximum(np.maximum(lo - y, y - hi), 0.0))
    out = np.concatenate(parts) if parts else np.zeros(0)
    return out, nominal_for, len(corners)


def creep_reserve(extensions: dict[str, Any] | None, records: list, delay: int) -> dict[str, Any]:
    """Creep the fitted bank could add beyond what the training records show (µm, µm/s).

    Creep is slow and driven by the input: a record without holds (a sine) shows
    only part of it, a step held until it settles shows all of it. With the fitted
    weights ``c_i`` (chosen or not: the creep candidate's fit) and the training
    input range ``R``, any input within that range gives ``|sum c_i (L_i u - u)| <=
    sum |c_i| R`` and a rate up to ``sum |c_i| R / tau_i``; the reserve is that worst
    case less the largest creep output and rate the training records show (those are
    already in the residual's disturbance). Zero when no creep was fitted.
    """
    row = (extensions or {}).get("candidates", {}).get("creep", {})
    weights, taus = row.get("weights"), row.get("taus_s")
    if not weights:
        return {"input": 0.0, "rate": 0.0, "worst": 0.0, "seen": 0.0}
    u_lo = min(float(np.min(r.u)) for r in records)
    u_hi = max(float(np.max(r.u)) for r in records)
    worst = sum(abs(w) for w in weights) * (u_hi - u_lo)
    worst_rate = sum(abs(w) / t for w, t in zip(weights, taus, strict=True)) * (u_hi - u_lo)
    seen, seen_rate = 0.0, 0.0
    for rec in records:
        u = delayed_input(rec.u, delay)
        c = sum(w * creep_response(u, rec.dt, t) for w, t in zip(weights, taus, strict=True))
        seen = max(seen, float(np.max(np.abs(c))))
        if c.size > 2:
            seen_rate = max(seen_rate, float(np.max(np.abs(np.gradient(c, rec.dt)))))
    return {
        "input": max(0.0, worst - seen),
        "rate": max(0.0, worst_rate - seen_rate),
        "worst": worst,
        "seen": seen,
    }


def coverage_note(coverage: float | None, details: dict[str, Any]) -> str | None:
    """A diagnostic when the held-out coverage is below :data:`COVERAGE_TARGET` (else None)."""
    if coverage is None or coverage >= COVERAGE_TARGET:
        return None
    full = details["band"].get("coverage_full_bound")
    tail = (
        f"; the bound written to the stage file, sized on the validation records too, "
        f"covers {100 * full:.2f} % of them"
        if full is not None
        else ""
    )
    return (
        f"The held-out coverage is {100 * coverage:.2f} %, below the "
        f"{100 * COVERAGE_TARGET:g} % asked: the {details['band']['heldout']} show "
        f"behaviour the training records do not (a larger or slower disturbance, drift, "
        f"creep, amplitudes outside the trained range){tail}. What would help: train on "
        "records like the held-out ones too (--data A --data B)."
    )
