"""The UKF baseline: exact plant step as process model, documented defaults, the
observers' interface."""

import math

import numpy as np
import pytest
from filterpy.common import Saver

from bwdesign import InputError, UnscentedObserver, preset, simulate_zoh, zoh_step
from bwdesign.model.plant import discretize
from bwdesign.observers.ukf import default_noise, max_hysteresis_slope

DT = 2e-4


def section41(T, seed=None, noise=0.0):
    p = preset("paper_simulation_corrected")
    n = int(round(T / DT))
    t = np.arange(n + 1) * DT
    u = 3.0 * np.sin(0.4 * np.pi * t[:-1] - 0.5 * np.pi) + 3.0
    X = simulate_zoh(p, u, DT, (10.0, 2.0, 2.0), u_prev=float(u[0]))
    z = X[1:, 0]
    if noise:
        z = z + noise * np.random.default_rng(seed).standard_normal(n)
    return p, t, u, X, z


def test_defaults_are_the_documented_ones(experiment):
    obs = UnscentedObserver(experiment, DT, udot_max=600.0, noise_std=0.02)
    h_max = experiment.alpha / (experiment.beta + experiment.gamma)
    slope = experiment.alpha + (experiment.beta - experiment.gamma) * h_max
    assert max_hysteresis_slope(experiment) == pytest.approx(slope)
    s_h = slope * 600.0 * DT
    g = discretize(experiment, DT).F[:, 2]
    np.testing.assert_allclose(obs.Q, s_h**2 * np.outer(g, g), rtol=1e-14)
    assert obs.Q[2, 2] == pytest.approx(s_h**2)
    np.testing.assert_allclose(obs.R, [[0.02**2]])
    np.testing.assert_allclose(obs.P, np.diag([h_max**2, experiment.a1 * h_max**2, h_max**2]))
    Q, R, P0 = default_noise(experiment, DT, udot_max=600.0, noise_std=0.02)
    np.testing.assert_array_equal(Q, obs.Q)
    assert "UnscentedObserver(plant='paper_experiment'" in repr(obs)


def test_process_model_is_the_exact_plant_step(experiment):
    """With a negligible spread the sigma points all follow zoh_step."""
    x0 = np.array([50.0, 100.0, 0.4])
    obs = UnscentedObserver(
        experiment, DT, Q=np.zeros((3, 3)), P0=np.diag([1e-16, 1e-12, 1e-16]), x0=x0,
        u_prev=30.0,
    )  # fmt: skip
    obs.predict(34.0)
    want = zoh_step(experiment, x0, 30.0, 34.0, DT)
    np.testing.assert_allclose(obs.x_prior, want, rtol=1e-9)
    np.testing.assert_array_equal(obs.x, obs.x_prior)
    assert obs.u_prev == 34.0


def test_converges_on_section_41_noise_free():
    p, t, u, X, z = section41(1.0)
    obs = UnscentedObserver(p, DT, udot_max=3.0 * 0.4 * np.pi, u_prev=float(u[0]))
    xh = obs.batch_filter(z, u)
    err = np.abs(xh - X[1:])
    assert err[0, 2] > 0.1  # x1 is measured; x3 starts wrong
    late = t[1:] >= 0.5
    assert np.all(err[late].max(axis=0) < 1e-5 * np.ptp(X, axis=0))


def test_filters_measurement_noise():
    p, t, u, X, z = section41(0.6, seed=4, noise=0.01)
    obs = UnscentedObserver(p, DT, udot_max=3.0 * 0.4 * np.pi, noise_std=0.01)
    obs.reset(u_prev=float(u[0]))
    xh = obs.batch_filter(z, u)
    late = t[1:] >= 0.2
    rmse = np.sqrt(np.mean((xh[late] - X[1:][late]) ** 2, axis=0))
    assert rmse[0] < 0.01  # better than the raw sensor
    assert rmse[2] < 0.02


def test_batch_filter_equals_loop_and_saver_records(experiment):
    rng = np.random.default_rng(8)
    n = 120
    u = 60.0 + 40.0 * np.sin(np.linspace(0.0, 3.0, n))
    X = simulate_zoh(experiment, u, DT, (1.0, 0.0, 0.1), u_prev=float(u[0]))
    zs = [float(v) for v in X[1:, 0] + 0.01 * rng.standard_normal(n)]
    zs[10] = zs[50] = None
    a = UnscentedObserver(experiment, DT, udot_max=600.0, u_prev=float(u[0]))
    b = UnscentedObserver(experiment, DT, udot_max=600.0, u_prev=float(u[0]))
    out = a.batch_filter(zs, u)
    saver = Saver(b)
    for uk, zk in zip(u, zs, strict=True):
        b.predict(uk)
        b.update(zk)
        saver.save()
    saver.to_array()
    scale = np.abs(saver.x).max(axis=0)
    assert np.max(np.abs(out - saver.x) / scale) <= 1e-12
    assert saver.P.shape == (n, 3, 3) and saver.x_prior.shape == (n, 3)
    np.testing.assert_array_equal(saver.x_post[10], saver.x_prior[10])  # skipped sample
    np.testing.assert_allclose(a.P, b.P, rtol=1e-12)
    assert a.u_prev == b.u_prev and a.y == b.y


BAD = [
    ("no-envelope", lambda p: UnscentedObserver(p, DT), "give udot_max"),
    (
        "udot-zero",
        lambda p: UnscentedObserver(p, DT, udot_max=0.0),
        r"udot_max \(V/s\) = 0 is outside the supported range \(0, 1e\+09\]",
    ),
    (
        "noise-negative",
        lambda p: UnscentedObserver(p, DT, udot_max=1.0, noise_std=-1.0),
        r"noise_std .* = -1 is outside .* \(0, inf\)",
    ),
    ("dt-zero", lambda p: UnscentedObserver(p, 0.0, udot_max=1.0), r"dt \(s\) = 0 is outside"),
    ("Q-shape", lambda p: UnscentedObserver(p, DT, Q=np.eye(2)), r"shape \(3, 3\)"),
    ("Q-asym", lambda p: UnscentedObserver(p, DT, Q=np.triu(np.ones((3, 3)))), "symmetric"),
    ("R-negative", lambda p: UnscentedObserver(p, DT, udot_max=1.0, R=-1.0), "semidefinite"),
    ("x0-nan", lambda p: UnscentedObserver(p, DT, udot_max=1.0, x0=(0, math.nan, 0)), "x0"),
]


@pytest.mark.parametrize(("fn", "match"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_settings_raise(experiment, fn, match):
    with pytest.raises(InputError, match=match):
        fn(experiment)


@pytest.mark.parametrize(
    ("method", "value", "match"),
    [("predict", math.nan, "u must be finite"), ("update", math.inf, "z must be finite")],
)
def test_bad_signals_raise(experiment, method, value, match):
    obs = UnscentedObserver(experiment, DT, udot_max=1.0)
    with pytest.raises(InputError, match=match):
        getattr(obs, method)(value)
