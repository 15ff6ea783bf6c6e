"""The exact inverse Bouc–Wen model per sample (bwdesign/model/inverse.py): the residual,
agreement with an independent root finder, the bracket outside the bounded class."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from bwdesign import InputError, Sine, Triangle, preset
from bwdesign.model.inverse import TOL, inverse_bound, inverse_input, inverse_step
from bwdesign.model.plant import hysteresis_increment

DT = 2e-4
REFERENCES = [
    Sine(amplitude=80.0, offset=100.0, frequency=1.0),
    Triangle(amplitude=90.0, offset=100.0, frequency=1.0),
    Sine(amplitude=80.0, offset=100.0, frequency=20.0),
]


def _targets(p, ref, t):
    pos, vel, acc = ref.evaluate(t)
    return acc + p.a2 * vel + p.a1 * pos


@pytest.mark.parametrize("ref", REFERENCES, ids=["sine1", "triangle1", "sine20"])
def test_inverse_solves_the_model_to_rounding(experiment, ref):
    """Every sample's residual a3 v - a1 H(h_k, u_k, v) - R_k is at rounding level (below
    1e-13 of its terms; measured 5.3e-15 on paper_experiment), and an independent brentq
    on the same bracket finds the same input to 1e-11 V."""
    p = experiment
    t = np.arange(1.0 / DT) * DT + DT / 2
    u, h = inverse_input(p, ref, t)
    R = _targets(p, ref, t)
    u_prev = np.r_[u[0], u[:-1]]
    h_prev = np.r_[0.0, h[:-1]]
    worst = 0.0
    for k in range(t.size):
        hk = hysteresis_increment(p, h_prev[k], u_prev[k], u[k])
        assert hk == h[k]  # the returned state is the model's after the jump
        res = p.a3 * u[k] - p.a1 * hk - R[k]
        worst = max(worst, abs(res) / (abs(p.a3 * u[k]) + abs(p.a1 * hk) + abs(R[k])))
    assert worst < 1e-13
    h_cap = inverse_bound(p)
    for k in range(1, t.size, 97):  # a spread of samples against scipy's brentq
        b = 1.0001 * max(abs(h_prev[k]), h_cap) + 1e-12
        lo, hi = sorted(((R[k] - p.a1 * b) / p.a3, (R[k] + p.a1 * b) / p.a3))
        f = lambda v, k=k: p.a3 * v - p.a1 * hysteresis_increment(p, h_prev[k], u_prev[k], v) - R[k]  # noqa: E731, E501
        ref_u = brentq(f, lo, hi, xtol=1e-15, rtol=1e-15)
        assert abs(u[k] - ref_u) < 1e-11


def test_inverse_step_from_any_guess_and_with_a_negative_a3(experiment):
    """The safeguard: a guess far off (clipped into the bracket, Newton or bisection) gives
    the same root; with a3 < 0 (the sign folded into the residual) the residual vanishes."""
    import dataclasses

    p = experiment
    h_cap = inverse_bound(p)
    h, u, r = 0.3, 40.0, p.a3 * 55.0 - p.a1 * 0.6
    base, hb = inverse_step(p, h, u, r, u, h_cap)
    for guess in (-1e6, -3.0, 55.0, 1e6, float(base)):
        v, hv = inverse_step(p, h, u, r, guess, h_cap)
        assert abs(v - base) <= 2 * TOL * (1 + abs(base)) and abs(hv - hb) < 1e-12
    neg = dataclasses.replace(p, a3=-p.a3)
    for guess in (u, -1e6, 1e6):
        v, hv = inverse_step(neg, h, u, -r, guess, h_cap)
        assert hv == hysteresis_increment(neg, h, u, v)
        assert abs(neg.a3 * v - neg.a1 * hv + r) < 1e-13 * abs(r)


def test_inverse_outside_the_bounded_class_says_so():
    p = preset("paper_simulation")  # beta < 0: no hysteresis bound, the bracket is checked
    t = np.arange(20) * 1e-5
    with pytest.raises(InputError, match="outside the bounded class"):
        inverse_input(p, Sine(amplitude=1.0, offset=0.0, frequency=100.0), t, allow_unbounded=True)
