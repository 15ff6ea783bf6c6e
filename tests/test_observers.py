"""Sampled PHSO and ESO: convergence, exactness against their twins, the continuous
forms, python-control interconnection, and typed errors on bad input."""

import math

import control
import numpy as np
import pytest
from filterpy.common import Saver
from scipy.integrate import solve_ivp

from bwdesign import (
    ExtendedStateObserver,
    GainError,
    HysteresisObserver,
    InputError,
    UnboundedModelError,
    preset,
    simulate_zoh,
)
from bwdesign.model.plant import discretize, rhs
from bwdesign.observers.dynamics import eso_rhs, eso_step, observer_iosystem, phso_rhs, phso_step
from bwdesign.observers.gains import C, discrete_gains, error_matrix

DT = 2e-4
GAINS_41 = [(40.0, 40.0, -80.0), (80.0, 160.0, -640.0)]
GAINS_EXP = (8.0, 64.0, -512.0)
OBSERVERS = [HysteresisObserver, ExtendedStateObserver]


def u41(t):
    """Section 4.1 input (V)."""
    return 3.0 * np.sin(0.4 * np.pi * np.asarray(t) - 0.5 * np.pi) + 3.0


def u_exp(t):
    """A 1 Hz sine over most of the experiment stage's range (V)."""
    return 70.0 + 60.0 * np.sin(2.0 * np.pi * np.asarray(t))


# plant, gains, input, true x0 (the estimate starts at zero), run length (s)
CASES = {
    "paper_simulation_corrected": ((80.0, 160.0, -640.0), u41, (10.0, 2.0, 2.0), 0.4),
    # the paper's gains leave a lightly damped error pair (-31 +- 351j)/s here
    "paper_experiment": (GAINS_EXP, u_exp, (10.0, 2.0, 0.8), 1.6),
}


def zoh_truth(p, u, T, x0, dt=DT):
    """Exact ZOH plant with u_k = u(t_k) held: the actuator a digital loop drives."""
    n = int(round(T / dt))
    t = np.arange(n + 1) * dt
    uk = u(t[:-1])
    X = simulate_zoh(p, uk, dt, x0, u_prev=float(uk[0]))
    return t, uk, X


@pytest.mark.parametrize("name", list(CASES))
def test_phso_converges_from_wrong_estimate(name):
    p = preset(name)
    gains, u, x0, T = CASES[name]
    t, uk, X = zoh_truth(p, u, T, x0)
    obs = HysteresisObserver(p, gains, DT, u_prev=float(uk[0]))
    xh = obs.batch_filter(X[1:, 0], uk)
    err = np.abs(xh - X[1:])
    scale = np.ptp(X[1:], axis=0)
    assert err[0, 0] > 1.0  # it did start wrong (by ~10 length units)
    late = t[1:] >= 0.75 * T
    # the model copy is exact, so the error decays to round-off
    assert np.all(err[late].max(axis=0) < 1e-9 * scale), err[late].max(axis=0) / scale
    # and the decay is monotone on average: each tenth of the run ends smaller
    tenths = [err[k * len(err) // 10 : (k + 1) * len(err) // 10].max() for k in range(10)]
    assert tenths[-1] < 1e-6 * tenths[0]


def _rmse_after(xh, X, t, t0):
    sel = t[1:] >= t0
    return np.sqrt(np.mean((xh[sel] - X[1:][sel]) ** 2, axis=0))


@pytest.mark.parametrize("gains", GAINS_41, ids=["40-40-80", "80-160-640"])
def test_section_41_phso_x3_error_10x_below_eso(simulation, gains):
    """Noise-free Section 4.1 at 0.2 ms, plant driven through a ZOH (digital loop).

    One full input period (5 s): the ESO lags most on the falling half, where
    dh/du is largest."""
    t, uk, X = zoh_truth(simulation, u41, 5.0, (10.0, 2.0, 2.0))
    rm = {}
    for cls in OBSERVERS:
        obs = cls(simulation, gains, DT, u_prev=float(uk[0]))
        rm[cls] = _rmse_after(obs.batch_filter(X[1:, 0], uk), X, t, 0.5)
    phso, eso = rm[HysteresisObserver][2], rm[ExtendedStateObserver][2]
    assert eso > 1e-3  # the ESO lags the hysteresis by a visible amount
    assert phso * 10.0 <= eso, (phso, eso)


def test_section_41_continuous_input_at_20us(simulation):
    """Same, with the plant driven by a smooth sine (fine ZOH grid, 4 us).

    The observers hold u over each 20 us sample, so the PHSO is no longer exact:
    the hold mismatch, O(dt), is what it has left. It still beats the ESO by 10x
    on x3 with either gain set.
    """
    dt, m, T = 2e-5, 5, 5.0
    tf, uf, Xf = zoh_truth(simulation, u41, T, (10.0, 2.0, 2.0), dt=dt / m)
    t, X, uk = tf[::m], Xf[::m], uf[::m]
    for gains in GAINS_41:
        rm = {}
        for cls in OBSERVERS:
            obs = cls(simulation, gains, dt, u_prev=float(uk[0]))
            rm[cls] = _rmse_after(obs.batch_filter(X[1:, 0], uk), X, t, 0.4)
        phso, eso = rm[HysteresisObserver][2], rm[ExtendedStateObserver][2]
        assert phso > 0  # not exact any more
        assert phso * 10.0 <= eso, (gains, phso, eso)


def _record(p, seed, n=400, missing=True):
    """A random held input, the true ZOH response and noisy measurements with gaps."""
    rng = np.random.default_rng(seed)
    span = 3.0 if p.a1 > 1e6 else 60.0
    u = span * (1.0 + np.sin(np.linspace(0, 6, n)) + 0.1 * rng.standard_normal(n))
    X = simulate_zoh(p, u, DT, (1.0, 0.0, 0.3), u_prev=0.0)
    z = X[1:, 0] + 0.01 * rng.standard_normal(n)
    zs = [float(v) for v in z]
    if missing:
        for k in rng.choice(n, 20, replace=False):
            zs[k] = None
    return u, zs


@pytest.mark.parametrize("cls", OBSERVERS, ids=["phso", "eso"])
def test_batch_filter_equals_predict_update_loop(usable_plant, cls):
    p = usable_plant
    u, zs = _record(p, seed=3)
    gains = GAINS_EXP if p.name == "paper_experiment" else GAINS_41[1]
    a = cls(p, gains, DT, x0=(0.5, 0.0, -0.2), u_prev=0.1)
    b = cls(p, gains, DT, x0=(0.5, 0.0, -0.2), u_prev=0.1)
    out = a.batch_filter(zs, u)
    loop = np.empty_like(out)
    for k, (uk, zk) in enumerate(zip(u, zs, strict=True)):
        b.predict(uk)
        b.update(zk)
        loop[k] = b.x
    scale = np.abs(loop).max(axis=0)
    np.testing.assert_allclose(out, loop, rtol=0, atol=1e-12 * scale.max())
    np.testing.assert_allclose(out / scale, loop / scale, rtol=0, atol=1e-12)
    for attr in ("x", "x_prior", "x_post"):
        np.testing.assert_allclose(getattr(a, attr), getattr(b, attr), rtol=1e-12, atol=0)
    assert a.u_prev == b.u_prev and a.z == b.z
    assert a.y == pytest.approx(b.y, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize(
    ("cls", "twin"),
    [(HysteresisObserver, phso_step), (ExtendedStateObserver, eso_step)],
    ids=["phso", "eso"],
)
def test_plain_function_twin_matches_class(usable_plant, cls, twin):
    p = usable_plant
    u, zs = _record(p, seed=5)
    gains = GAINS_EXP if p.name == "paper_experiment" else GAINS_41[0]
    obs = cls(p, gains, DT, x0=(0.0, 1.0, 0.1))
    zoh = discretize(p, DT)
    x, up = np.array([0.0, 1.0, 0.1]), 0.0
    priors, posts, twin_priors, twin_posts = [], [], [], []
    for uk, zk in zip(u, zs, strict=True):
        obs.predict(uk)
        priors.append(obs.x_prior.copy())
        obs.update(zk)
        posts.append(obs.x_post.copy())
        prior, x = twin(p, zoh, obs.K, x, up, uk, zk)
        twin_priors.append(prior)
        twin_posts.append(x)
        up = uk
    for ours, theirs in ((priors, twin_priors), (posts, twin_posts)):
        ours, theirs = np.array(ours), np.array(theirs)
        scale = np.abs(theirs).max(axis=0)
        assert np.max(np.abs(ours - theirs) / scale) <= 1e-12


def test_update_none_skips_and_size_one_array_is_accepted(experiment):
    obs = HysteresisObserver(experiment, GAINS_EXP, DT)
    obs.predict(5.0)
    prior = obs.x_prior.copy()
    obs.update(None)
    np.testing.assert_array_equal(obs.x, prior)
    np.testing.assert_array_equal(obs.x_post, prior)
    assert obs.y == 0.0 and obs.z is None
    twin = HysteresisObserver(experiment, GAINS_EXP, DT)
    twin.predict(5.0)
    obs.predict(6.0)
    twin.predict(6.0)
    obs.update(np.array([0.25]))  # filterpy-style z of shape (dim_z,)
    twin.update(0.25)
    np.testing.assert_array_equal(obs.x, twin.x)
    assert obs.y == pytest.approx(0.25 - obs.x_prior[0])


def test_saver_records_a_run(experiment):
    u, zs = _record(experiment, seed=7, n=50, missing=False)
    obs = HysteresisObserver(experiment, GAINS_EXP, DT)
    ref = HysteresisObserver(experiment, GAINS_EXP, DT).batch_filter(zs, u)
    saver = Saver(obs)
    for uk, zk in zip(u, zs, strict=True):
        obs.predict(uk)
        obs.update(zk)
        saver.save()
    saver.to_array()
    assert saver.x.shape == (50, 3)
    np.testing.assert_allclose(saver.x, ref, rtol=1e-12, atol=0)
    np.testing.assert_allclose(saver.x_post, ref, rtol=1e-12, atol=0)
    assert saver.x_prior.shape == (50, 3)
    assert not np.allclose(saver.x_prior, saver.x_post)
    np.testing.assert_allclose(saver.u_prev, u)
    np.testing.assert_allclose(saver.y, np.asarray(zs) - saver.x_prior[:, 0], rtol=1e-12)


def test_from_discrete_gains_matches_continuous_gains(simulation):
    a = HysteresisObserver(simulation, GAINS_41[0], DT)
    b = HysteresisObserver(simulation, discrete=discrete_gains(simulation, GAINS_41[0], DT), dt=DT)
    u, zs = _record(simulation, seed=11, n=100)
    np.testing.assert_array_equal(a.batch_filter(zs, u), b.batch_filter(zs, u))
    assert b.gains is None
    assert "discrete=" in repr(b) and "gains=[40.0, 40.0, -80.0]" in repr(a)
    assert repr(a).startswith("HysteresisObserver(plant='paper_simulation_corrected'")


@pytest.mark.parametrize("name", ["paper_experiment", "paper_simulation_corrected"])
@pytest.mark.parametrize("dt", [5e-5, 2e-4, 1e-3])
@pytest.mark.parametrize(
    "gains", [GAINS_EXP, *GAINS_41], ids=["8-64-512", "40-40-80", "80-160-640"]
)
def test_discrete_poles_are_exp_of_continuous_poles(name, dt, gains):
    p = preset(name)
    F = discretize(p, dt).F
    K = discrete_gains(p, gains, dt)
    got = np.linalg.eigvals(F - np.outer(K, C @ F))
    want = np.exp(np.linalg.eigvals(error_matrix(p, gains)) * dt)
    key = lambda z: (round(z.real, 6), round(z.imag, 6))  # noqa: E731
    got, want = sorted(got, key=key), sorted(want, key=key)
    np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-12)


def test_discrete_observer_converges_to_continuous_first_order(experiment):
    """Discrete PHSO (u held, z = y(t_{k+1})) against solve_ivp of eq. (3) with a smooth
    input and its exact derivative: the gap shrinks as dt, observed order ~1."""
    p, g = experiment, GAINS_EXP
    w = 2 * np.pi * 2.0

    def u(t):
        return 60.0 + 40.0 * np.sin(w * t)

    def udot(t):
        return 40.0 * w * np.cos(w * t)

    def joint(t, s):
        return np.concatenate(
            [rhs(p, s[:3], u(t), udot(t)), phso_rhs(p, g, s[3:], u(t), udot(t), s[0])]
        )

    T, xh0 = 0.25, np.array([-5.0, 0.0, 0.5])
    sol = solve_ivp(
        joint, (0, T), np.concatenate([np.zeros(3), xh0]), method="DOP853",
        rtol=1e-11, atol=1e-10, dense_output=True,
    )  # fmt: skip
    dts = np.array([1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5])
    errs = []
    for dt in dts:
        t = np.arange(int(round(T / dt)) + 1) * dt
        S = sol.sol(t)
        obs = HysteresisObserver(p, g, dt, x0=xh0, u_prev=u(0.0))
        xh = obs.batch_filter(S[0, 1:], u(t[:-1]))
        gap = np.abs(xh - S[3:, 1:].T) / np.ptp(S[3:], axis=1)
        errs.append(gap.max(axis=0))
    errs = np.array(errs)
    assert np.all(np.diff(errs, axis=0) < 0)  # every halving helps, every state
    orders = [np.polyfit(np.log(dts), np.log(errs[:, j]), 1)[0] for j in range(3)]
    assert min(orders) >= 0.9, orders
    assert max(orders) <= 1.3, orders  # first order (the held input), not better
    assert errs[-1].max() < 0.01


@pytest.mark.parametrize(("kind", "f"), [("phso", phso_rhs), ("eso", eso_rhs)], ids=["phso", "eso"])
def test_iosystem_dynamics_are_the_continuous_rhs(simulation, kind, f):
    sys = observer_iosystem(simulation, GAINS_41[1], kind=kind)
    assert sys.input_labels == ["u", "udot", "y"]
    assert sys.output_labels == ["xhat[0]", "xhat[1]", "xhat[2]"]
    assert sys.nstates == 3 and sys.name == kind
    rng = np.random.default_rng(2)
    for _ in range(5):
        x, (u, ud, y) = rng.normal(size=3), rng.normal(size=3) * (3.0, 20.0, 1.0)
        np.testing.assert_allclose(
            sys.dynamics(0.0, x, [u, ud, y]), f(simulation, GAINS_41[1], x, u, ud, y)
        )
        np.testing.assert_array_equal(sys.output(0.0, x, [u, ud, y]), x)


@pytest.mark.parametrize("cls", OBSERVERS, ids=["phso", "eso"])
def test_iosystem_interconnected_with_plant_simulates(experiment, cls):
    p = experiment
    plant = control.nlsys(
        lambda t, x, u, _: rhs(p, x, u[0], u[1]),
        lambda t, x, u, _: x[:1],
        inputs=["u", "udot"],
        states=["x[0]", "x[1]", "x[2]"],
        outputs=["y"],
        name="plant",
    )
    obs = cls(p, GAINS_EXP, DT).as_iosystem()
    loop = control.interconnect(
        [plant, obs], inplist=["u", "udot"], outlist=["y", "xhat"], name="loop"
    )
    assert loop.ninputs == 2 and loop.noutputs == 4 and loop.nstates == 6
    t = np.linspace(0.0, 0.3, 301)
    w = 2 * np.pi * 3.0
    u, ud = 60.0 + 40.0 * np.sin(w * t), 40.0 * w * np.cos(w * t)
    x0 = [10.0, 0.0, 0.5, 0.0, 0.0, 0.0]
    resp = control.input_output_response(
        loop, t, [u, ud], initial_state=x0, solve_ivp_kwargs={"rtol": 1e-9, "atol": 1e-9}
    )
    assert resp.success
    err = np.abs(resp.states[3:] - resp.states[:3])
    assert err[0, 0] == 10.0
    if cls is HysteresisObserver:  # exact model copy: the error dies out
        assert err[:, -1].max() < 1e-4 * np.abs(resp.states[:3]).max()
        assert err[2, -1] < 1e-6
    else:  # the ESO keeps a lag on the moving hysteresis
        assert 1e-2 < err[2, t > 0.15].max() < 2.0
    np.testing.assert_allclose(resp.outputs[1:], resp.states[3:])


def test_as_iosystem_needs_continuous_gains(experiment):
    obs = HysteresisObserver(experiment, discrete=discrete_gains(experiment, GAINS_EXP, DT), dt=DT)
    with pytest.raises(GainError, match="built from discrete gains K"):
        obs.as_iosystem()


def _phso(**kw):
    args = {"params": preset("paper_experiment"), "gains": GAINS_EXP, "dt": DT} | kw
    return HysteresisObserver(**args)


def _run(method, *args):
    def go():
        obs = _phso()
        if method == "update":
            obs.predict(1.0)
        getattr(obs, method)(*args)

    return go


A2 = preset("paper_experiment").a2
BAD = [
    (
        "gains-length-2",
        lambda: _phso(gains=(8.0, 64.0)),
        GainError,
        r"three numbers .* shape \(2,\)",
    ),
    ("gains-length-4", lambda: _phso(gains=(1, 2, 3, 4)), GainError, "three numbers"),
    ("gains-not-numbers", lambda: _phso(gains="abc"), GainError, "three numbers"),
    ("gains-nan", lambda: _phso(gains=(8.0, math.nan, -512.0)), GainError, "must be finite"),
    ("hurwitz-l1+a2", lambda: _phso(gains=(-A2 - 1.0, 64.0, -512.0)), GainError, r"l1 \+ a2 > 0"),
    (
        "hurwitz-second",
        lambda: _phso(gains=(8.0, 64.0, -1e6)),
        GainError,
        r"violate \(l1 \+ a2\)\(l1 a2 \+ a1 \+ l2\) \+ l3 a1 > 0",
    ),
    ("hurwitz-l3-positive", lambda: _phso(gains=(8.0, 64.0, 512.0)), GainError, "l3 a1 < 0"),
    ("hurwitz-l3-zero", lambda: _phso(gains=(8.0, 64.0, 0.0)), GainError, "l3 must be negative"),
    (
        "gains-and-discrete",
        lambda: _phso(discrete=(0.1, 1.0, -0.1)),
        GainError,
        "either continuous gains .* or discrete=K",
    ),
    (
        "discrete-unstable",
        lambda: _phso(gains=None, discrete=(0.0, 0.0, 5.0)),
        GainError,
        "unstable",
    ),
    ("dt-zero", lambda: _phso(dt=0.0), InputError, r"dt \(s\) = 0 is outside .* \[1e-09, 1\] s"),
    ("dt-negative", lambda: _phso(dt=-2e-4), InputError, r"dt \(s\) = -0.0002 is outside"),
    ("dt-nan", lambda: _phso(dt=math.nan), InputError, r"dt \(s\) must be finite, got nan"),
    ("dt-string", lambda: _phso(dt="2e-4"), InputError, r"dt \(s\) must be a number, got str"),
    ("x0-shape", lambda: _phso(x0=(1.0, 2.0)), InputError, r"x0 must be .* shape \(3,\)"),
    ("u-nan", _run("predict", math.nan), InputError, "u must be finite, got nan"),
    ("u-inf", _run("predict", math.inf), InputError, "u must be finite, got inf"),
    ("u-text", _run("predict", "1 V"), InputError, "u must be a number"),
    ("z-nan", _run("update", math.nan), InputError, "z must be finite, got nan"),
    ("z-inf", _run("update", -math.inf), InputError, "z must be finite, got -inf"),
    ("z-vector", _run("update", np.ones(2)), InputError, r"z must be a single number"),
    (
        "batch-z-nan",
        _run("batch_filter", np.array([0.0, math.nan]), [1.0, 2.0]),
        InputError,
        r"z must be finite, got zs\[1\] = nan",
    ),
    (
        "batch-z-nan-list",
        _run("batch_filter", [0.0, None, math.nan], [1.0, 2.0, 3.0]),
        InputError,
        "z must be finite",
    ),
    (
        "batch-u-inf",
        _run("batch_filter", [0.0, 0.0], [1.0, math.inf]),
        InputError,
        r"u must be finite, got us\[1\] = inf",
    ),
    (
        "batch-lengths",
        _run("batch_filter", [0.0, 0.0, 0.0], [1.0, 2.0]),
        InputError,
        "same length",
    ),
    (
        "unbounded-model",
        lambda: _phso(params=preset("paper_simulation"), gains=GAINS_41[0]),
        UnboundedModelError,
        "outside the bounded Bouc-Wen class",
    ),
    (
        "iosystem-kind",
        lambda: observer_iosystem(preset("paper_experiment"), GAINS_EXP, kind="ekf"),
        ValueError,
        "kind must be 'phso', 'eso' or 'phdo'",
    ),
    (
        "iosystem-gains",
        lambda: observer_iosystem(preset("paper_experiment"), (8.0, 64.0, 1.0)),
        GainError,
        "l3 a1 < 0",
    ),
]


@pytest.mark.parametrize(("fn", "exc", "match"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_raises_typed_error(fn, exc, match):
    with pytest.raises(exc, match=match):
        fn()


def test_typed_errors_are_value_errors():
    assert issubclass(GainError, ValueError) and issubclass(InputError, ValueError)


def test_eso_also_skips_and_resets(experiment):
    obs = ExtendedStateObserver(experiment, GAINS_EXP, DT, x0=(1.0, 2.0, 3.0), u_prev=4.0)
    obs.predict(4.0)
    assert obs.x[2] == 3.0  # x3 held by the ESO's predict
    obs.update(None)
    obs.reset()
    np.testing.assert_array_equal(obs.x, np.zeros(3))
    assert obs.u_prev == 0.0 and obs.z is None


def test_import_does_not_load_matplotlib_control_or_filterpy():
    import subprocess
    import sys

    code = (
        "import sys, bwdesign; "
        "print(sorted(m for m in ('matplotlib', 'control', 'filterpy') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_observer_plots_render(tmp_path, experiment):
    from bwdesign.plotting.figures import plot_estimation_errors, plot_observer_states, save_figure

    u, zs = _record(experiment, seed=1, n=200, missing=False)
    X = simulate_zoh(experiment, u, DT, (1.0, 0.0, 0.3), u_prev=0.0)[1:]
    t = np.arange(1, 201) * DT
    est = {
        cls.kind.upper(): cls(experiment, GAINS_EXP, DT).batch_filter(zs, u) for cls in OBSERVERS
    }
    fig, axes = plot_observer_states(t, X, est, t_zoom=0.02, title="smoke")
    assert axes.shape == (3, 2)
    assert [ln.get_label() for ln in axes[0, 0].get_lines()] == ["true", "PHSO", "ESO"]
    save_figure(fig, tmp_path / "states.png")
    curves = {f"x3 | {k} dt = 0.2 ms": (t, v[:, 2] - X[:, 2]) for k, v in est.items()}
    fig, axes = plot_estimation_errors(curves, title="smoke")
    assert axes.shape == (1, 1)
    save_figure(fig, tmp_path / "errors.png")
    for f in ("states.png", "errors.png"):
        assert (tmp_path / f).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
