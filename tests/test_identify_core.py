"""Identification: the fit's simulator, the bounded parametrisation, and quick round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bwdesign import (
    BoucWenParams,
    IdentificationResult,
    ParameterError,
    identify,
    preset,
    simulate_zoh,
)
from bwdesign.identify.excite import design_excitation, simulate_record
from bwdesign.identify.problem import params_from_theta
from bwdesign.identify.simulate import linear_matrices, simulate_output
from bwdesign.model.plant import discretize

NAMES = ("a1", "a2", "a3", "alpha", "beta", "gamma")

#: A stage with gamma < 0 (bounded: beta + gamma > 0, beta - gamma >= 0), 300 Hz.
GAMMA_NEGATIVE = BoucWenParams(
    a1=3553057.6, a2=376.99, a3=2842446.1, alpha=0.3, beta=0.05, gamma=-0.03, name="gneg"
)


@pytest.mark.parametrize(
    "plant",
    [preset("paper_experiment"), preset("paper_simulation_corrected"), GAMMA_NEGATIVE],
    ids=["experiment", "simulation_corrected", "gamma_negative"],
)
@pytest.mark.parametrize("dt", [1e-5, 2e-4, 5e-3])
def test_fit_simulator_is_the_exact_zoh_plant(plant, dt):
    rng = np.random.default_rng(0)
    n = 400
    u = 3 + np.cumsum(rng.standard_normal(n)) * 0.5
    x0 = np.array([1.0, 20.0, 0.2])
    ref = simulate_zoh(plant, u, dt, x0, u_prev=u[0])[1:, 0]
    got = simulate_output(plant, u, dt, x0, offset=0.0)
    assert np.max(np.abs(got - ref)) <= 1e-9 * max(1.0, np.max(np.abs(ref)))


@pytest.mark.parametrize("zeta", [0.0, 0.01, 0.7, 1.0, 1.0 + 1e-9, 3.0, 300.0])
@pytest.mark.parametrize("wn_dt", [1e-4, 0.1, 3.0])
def test_closed_form_matrices_match_discretize(zeta, wn_dt):
    a1 = 1.6e5
    dt = wn_dt / math.sqrt(a1)
    a2 = 2 * zeta * math.sqrt(a1)
    phi, b = linear_matrices(a1, a2, dt)
    zoh = discretize(BoucWenParams(a1=a1, a2=a2, a3=a1, alpha=1.0, beta=1.0, gamma=0.0), dt)
    s = np.diag([1.0, math.sqrt(a1)])
    assert np.allclose(np.linalg.solve(s, phi - zoh.F[:2, :2]) @ s, 0.0, atol=1e-10)
    assert np.allclose((b + zoh.F[:2, 2]) / np.array([1.0, math.sqrt(a1)]), 0.0, atol=1e-10)


def test_start_grid_computed_together_equals_one_at_a_time():
    """The batched start grid (paths of several shapes in one pass, one QR of the shared
    columns) gives each point's projection as the per-point solve does, to rounding,
    on an input with reversals, holds and both branches of the shape."""
    from bwdesign.identify.simulate import Segments, hysteresis_path, hysteresis_paths
    from bwdesign.identify.stack import Stack

    rng = np.random.default_rng(4)
    t = np.arange(3000) * 1e-3
    u = 60 + 50 * np.sin(2 * np.pi * t) * np.exp(-t / 3) + np.round(5 * rng.standard_normal(t.size))
    u[1000:1200] = u[1000]  # a hold
    seg = Segments(u)
    betas = np.array([0.001, 0.01, 0.05, 0.2])
    gammas = betas * np.tanh(np.array([-2.0, 0.0, 1.0, 2.5]))
    h0 = np.array([-3.0, 0.0, 2.0, 40.0])
    many = hysteresis_paths(seg, h0, 0.7, betas + gammas, betas - gammas)
    for g in range(betas.size):
        one = hysteresis_path(u, h0[g], 0.7, betas[g], gammas[g], segments=seg)
        assert np.max(np.abs(many[:, g] - one)) <= 1e-12 * (1 + np.max(np.abs(one)))
    plant = preset("paper_experiment")
    rec = simulate_record(plant, u, 1e-3, noise=0.01, offset=2.0, seed=2)
    prob = Stack.build([rec], 1.0)
    base = np.zeros(10)
    base[2], base[1] = math.log(600.0), math.log(2 * 0.7 / 600.0)
    grid = []
    for lb in (-6.0, -4.0, -1.0):
        for q in (-1.0, 0.0, 1.0):
            th = base.copy()
            th[4], th[5], th[7] = lb, q, 0.5
            grid.append(th)
    singles = [prob.project(g) for g in grid]
    assert any(math.isfinite(c) for c, _ in singles)
    for (c1, t1), (c2, t2) in zip(prob.project_many(grid), singles, strict=True):
        assert (math.isinf(c1) and math.isinf(c2)) or abs(c1 - c2) <= 1e-9 * abs(c2)
        assert np.allclose(t1, t2, rtol=1e-8, atol=1e-10)


def test_every_fit_vector_is_in_the_bounded_class():
    rng = np.random.default_rng(1)
    for _ in range(500):
        th = rng.uniform(-20, 20, size=10)
        th[5] = rng.uniform(-8, 8)
        p = params_from_theta(th, 1.0)
        assert p.bounded_class().bounded, (p.beta, p.gamma)


def _record(plant, dt, duration, *, seed, umin=0.0, umax=100.0, udot=3000.0, offset=3.0):
    _, u = design_excitation(
        plant, umin=umin, umax=umax, udot_max=udot, duration=duration, dt=dt, seed=seed
    )
    return simulate_record(plant, u, dt, noise=0.01, offset=offset, seed=seed + 10), u


def test_quick_round_trip_without_init():
    plant = GAMMA_NEGATIVE
    train, u = _record(plant, 1e-4, 0.3, seed=0)
    valid = simulate_record(plant, u[::-1].copy(), 1e-4, noise=0.01, offset=3.0, seed=99)
    res = identify(train, validation=valid, multistart=1)
    assert isinstance(res, IdentificationResult)
    assert res.converged, res.reason
    for n in NAMES:
        true, got = getattr(plant, n), getattr(res.params, n)
        assert abs(got / true - 1) < 0.01, (n, got, true)
        lo, hi = res.ci95[n]
        assert lo < got < hi
    assert res.fit_percent["validation"] >= 99.5
    assert abs(res.offset - 3.0) < 0.01
    assert res.residual_rms == pytest.approx(0.01, rel=0.1)
    assert res.delay_samples == 0
    assert all(res.determined.values())
    assert res.diagnostics == ()
    assert res.params.bounded_class().bounded
    doc = res.to_dict()
    assert set(doc["params"]) == set(NAMES) and set(doc["ci95"]) == set(NAMES)
    assert np.allclose(np.diag(res.correlation), 1.0)
    box = res.to_uncertainty()
    assert box.source == "identified" and box.level == 0.95
    assert box.half_width("a1", res.params) == pytest.approx(res.ci95["a1"][1] - res.params.a1)
    # the identified box is the one type: its checked bounds are the 95 % intervals
    checked = box.check(res.params)
    assert list(checked) == list(NAMES)
    for n in NAMES:
        assert checked[n] == pytest.approx(res.ci95[n], rel=1e-12)


def test_delay_of_one_sample_is_found():
    """A logger that stamps y at the start of the sample: y[k] = x1(t_k)."""
    plant = GAMMA_NEGATIVE
    rec, u = _record(plant, 1e-4, 0.3, seed=2)
    late = type(rec).from_arrays(rec.t[1:], u[1:], rec.y[:-1])
    res = identify(late, multistart=1)
    assert res.delay_samples == 1
    assert any("delay of 1 sample" in d for d in res.diagnostics)
    assert abs(res.params.a1 / plant.a1 - 1) < 0.01


@pytest.mark.parametrize("fs", [200.0, 1000.0])
def test_slow_sine_bench_record_offset_mid_cycle(fs):
    """The commonest bench record: 1 Hz sine, offset, no rest at the start, resonance unseen."""
    plant = preset("paper_experiment")
    dt = 1.0 / fs
    n_pre, n = int(1.3 * fs), int(3 * fs)
    t = np.arange(n_pre + n) * dt
    u = 60 + 50 * np.sin(2 * np.pi * t + 0.4)
    x = simulate_zoh(plant, u[:n_pre], dt, np.zeros(3), u_prev=u[0])
    rec = simulate_record(plant, u[n_pre:], dt, noise=0.01, offset=7.0, x0=tuple(x[-1]), seed=3)
    res = identify(rec, multistart=1)
    assert res.converged, res.reason
    assert res.fit_percent["train"] > 99.5
    for n_ in ("a1", "a2", "a3"):
        assert not res.determined[n_]
        assert res.ci95[n_] == (-math.inf, math.inf)
    assert any("NOT determined" in d and "resonance" in d for d in res.diagnostics)
    assert res.derived["static_gain"]["value"] == pytest.approx(plant.static_gain, rel=2e-3)
    assert abs(res.offset - 7.0) < 0.05
    for n_ in ("alpha", "beta"):
        assert res.determined[n_]
        assert abs(getattr(res.params, n_) / getattr(plant, n_) - 1) < 0.02
    box = res.to_uncertainty()
    assert box.undetermined() == ("a1", "a2", "a3")
    with pytest.raises(ParameterError, match="leaves a1, a2, a3 not determined"):
        box.check(res.params)  # what every user of the box (sweep, certificates) says


def test_poor_excitation_says_what_is_not_determined():
    """A small ramp that never reverses: the loop shape is not in the data."""
    plant = preset("paper_experiment")
    dt = 2e-4
    t = np.arange(2000) * dt
    u = 10 + 0.8 * t / t[-1]
    rec = simulate_record(plant, u, dt, noise=0.01, offset=1.0, seed=4)
    res = identify(rec, multistart=1)
    assert not res.determined["beta"] and not res.determined["gamma"]
    text = " ".join(res.diagnostics)
    assert "never reversed" in text
    assert "beta" in text and "gamma" in text
    for n in ("beta", "gamma"):
        lo, hi = res.ci95[n]
        half = 0.5 * (hi - lo)
        assert not half < 0.5 * abs(getattr(res.params, n))


def test_init_and_fixed():
    plant = GAMMA_NEGATIVE
    rec, _ = _record(plant, 1e-4, 0.3, seed=5)
    res = identify(rec, init=plant.replace(alpha=0.25), fixed=("a1", "a2"), multistart=1)
    assert res.params.a1 == pytest.approx(plant.a1)
    assert res.params.a2 == pytest.approx(plant.a2)
    assert abs(res.params.alpha / plant.alpha - 1) < 0.01


def test_not_converged_is_reported():
    plant = GAMMA_NEGATIVE
    rec, _ = _record(plant, 1e-4, 0.3, seed=6)
    res = identify(rec, multistart=1, max_nfev=1)
    assert not res.converged
    assert "evaluations" in res.reason
