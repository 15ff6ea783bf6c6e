"""Closed-loop simulation: sampled and continuous paths, options, CLI."""

import dataclasses
import json
import math

import numpy as np
import pytest

from bwdesign import (
    ClosedLoop,
    ContinuousSolver,
    DiscreteTrackingController,
    HysteresisObserver,
    ObserverSpec,
    Sine,
    Start,
    Step,
    Triangle,
    make_controller,
    simulate,
    simulate_continuous,
)
from bwdesign.cli.main import main
from bwdesign.design.tuning import observer_gains
from bwdesign.errors import GainError, InputError, UnboundedModelError
from bwdesign.output.jsonenc import json_safe
from bwdesign.sim.continuous import _solve_udot
from bwdesign.sim.metrics import steady_state_window

DT = 2e-4
SINE = Sine(amplitude=80.0, offset=100.0, frequency=1.0)
FAST = (2286.2, 1208280.0, -6256.75)  # triple observer pole at 1000 rad/s on paper_experiment


def tuned(p, **kw):
    """The tuned discrete law: lambda1 = lambda2 = 240 1/s, integral action at 120 1/s."""
    return make_controller(p, 240.0, 240.0, form="discrete", dt=DT, integral_rate=120.0, **kw)


def loop(p, observer="phso", *, gains=FAST, controller=None, **kw):
    """``observer`` on ``gains`` (none for the UKF) with ``controller`` (default :func:`tuned`)."""
    spec = ObserverSpec.of(observer, None if observer == "ukf" else gains)
    return ClosedLoop(p, spec, tuned(p) if controller is None else controller, dt=DT, **kw)


def test_tracking_error_decays(experiment):
    r = simulate(loop(experiment), SINE, duration=2.0)
    assert r.stable and r.status == "ok"
    assert abs(r.e[0]) == pytest.approx(100.0)  # starts at rest at 0, reference at 100
    assert r.metrics.maxe < 0.05 and r.metrics.me < 0.01
    assert r.window == steady_state_window(r.t, SINE.period)
    assert np.max(np.abs(r.e[r.t > 1.0])) < 1e-3 * np.max(np.abs(r.e[r.t < 0.05]))
    assert r.estimation_rmse[0] < 1e-6  # exact model, exact initial estimate


def test_phso_beats_eso_nominal(experiment):
    res = {o: simulate(loop(experiment, o), SINE, duration=3.0) for o in ("phso", "eso")}
    assert res["phso"].metrics.me < res["eso"].metrics.me
    assert res["phso"].metrics.rmse < res["eso"].metrics.rmse
    assert res["phso"].estimation_rmse[2] < res["eso"].estimation_rmse[2]


def test_fast_path_equals_generic_path(experiment):
    """The scalar-inlined runner and the object runner give the same record."""
    tp = experiment.replace(a1=experiment.a1 * 1.01)
    ctrl = tuned(
        experiment,
        u_limits=(-30.0, 150.0),
        estimate_limits=((-50.0, 250.0), None, (-5.0, 5.0)),
    )
    for obs in ("phso", "eso"):
        for delay, comp in ((False, True), (True, True), (True, False)):
            lp = loop(experiment, obs, controller=ctrl, delay=delay, compensate_delay=comp)
            kw = dict(duration=0.3, noise_std=0.02, seed=4, true_params=tp)
            a = simulate(lp, SINE, fast=True, **kw)
            b = simulate(lp, SINE, fast=False, **kw)
            assert a.settings["path"] == "fast" and b.settings["path"] == "generic"
            np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9)
            np.testing.assert_allclose(a.u, b.u, rtol=0, atol=1e-9)
            np.testing.assert_allclose(a.xhat, b.xhat, rtol=0, atol=1e-9)


@pytest.mark.parametrize("observer", ["phso", "eso", "phdo"])
def test_the_compiled_step_is_the_python_step_to_the_bit(experiment, monkeypatch, observer):
    """The fast path runs the compiled step; the Python-float step of bwdesign.sim.kernel
    gives the very same floats: delays, limits, integral action, noise, a disturbance, a
    mismatched plant and a divergence (the same sample, the same message)."""
    import importlib

    cl = importlib.import_module("bwdesign.sim.closed_loop")
    importlib.import_module("bwdesign.sim.compiled")  # loaded: short runs take it too
    tp = experiment.replace(a1=experiment.a1 * 1.02, beta=experiment.beta * 0.9)
    ctrl = tuned(experiment, u_limits=(-30.0, 150.0), estimate_limits=((-50.0, 250.0), None, None))
    from bwdesign.observers.gains import disturbance_gains_from

    gains = FAST if observer != "phdo" else disturbance_gains_from(FAST)
    runs = [
        (loop(experiment, observer, gains=gains, controller=ctrl, delay=d, compensate_delay=c),
         dict(true_params=tp, noise_std=0.02, seed=3, input_disturbance=lambda t: np.sin(9 * t)))
        for d, c in ((False, True), (True, True), (True, False))
    ]  # fmt: skip
    runs.append(
        (loop(experiment, observer, gains=gains), dict(true_params=tp.replace(a3=-tp.a3)))
    )  # the sign of the input reversed: it diverges
    for lp, kw in runs:
        a = simulate(lp, Triangle(amplitude=60, offset=90, frequency=2), duration=0.3, **kw)
        monkeypatch.setattr(cl, "COMPILED_STEP", False)
        b = simulate(lp, Triangle(amplitude=60, offset=90, frequency=2), duration=0.3, **kw)
        monkeypatch.undo()
        assert a.status == b.status and a.settings["path"] == "fast"
        for name in ("x", "xhat", "u", "z"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.status.startswith("diverged at t = ") and not b.stable


def test_hysteresis_jump_fast_equals_generic(experiment):
    lp = loop(experiment, controller=tuned(experiment, hysteresis_jump=True))
    a = simulate(lp, SINE, duration=0.2)
    b = simulate(lp, SINE, duration=0.2, fast=False)
    np.testing.assert_allclose(a.u, b.u, atol=1e-9)


def test_noise_is_seeded(experiment):
    lp, kw = loop(experiment, "eso"), dict(duration=0.2, noise_std=0.02)
    a = simulate(lp, SINE, seed=7, **kw)
    b = simulate(lp, SINE, seed=7, **kw)
    c = simulate(lp, SINE, seed=8, **kw)
    np.testing.assert_array_equal(a.z, b.z)
    assert not np.array_equal(a.z, c.z)
    assert np.std(a.z - a.x[:, 0]) == pytest.approx(0.02, rel=0.1)


def test_divergence_is_reported_not_raised(experiment):
    """Eq. (12) with the Section 4.2 lambda1 = 2.2e6 sampled at 0.2 ms blows up."""
    lp = loop(
        experiment,
        gains=(8.0, 64.0, -512.0),
        controller=make_controller(experiment, 2.2e6, 80.0),
    )
    r = simulate(lp, SINE, duration=1.0)
    assert not r.stable and r.metrics is None and r.estimation_rmse is None
    assert r.status.startswith("diverged at t = ")
    assert r.t.size < 5000 and np.all(np.isfinite(r.x))
    doc = r.to_dict()
    assert doc["stable"] is False and doc["metrics"] is None
    json.dumps(json_safe(doc))


def test_input_limits_hold_and_drive_the_observer(experiment):
    r = simulate(
        loop(experiment, controller=tuned(experiment, u_limits=(-30.0, 60.0))),
        Step(amplitude=100.0, offset=20.0, t_step=0.02),
        duration=0.1,
    )
    assert r.u.max() <= 60.0 and r.u.min() >= -30.0
    assert r.saturated_fraction > 0
    # the observer saw the clipped input: its estimate stays exact
    assert np.max(np.abs(r.xhat - r.x)) < 1e-6


def test_smoothed_step_removes_the_input_peak(experiment):
    """The peaking remedy: a quintic rise instead of a sharp step."""
    g = tuple(observer_gains(experiment, [-5000.0] * 3))
    start = Start(x0=(20.0, 0.0, 0.0), xhat0=(20.0, 0.0, 0.0),
                  u_prev=20.0 * experiment.a1 / experiment.a3)  # fmt: skip
    ctrl = make_controller(experiment, 1000.0, 1000.0, form="discrete", dt=DT)
    lp = loop(experiment, "eso", gains=g, controller=ctrl, start=start)
    sharp = simulate(lp, Step(amplitude=100.0, offset=20.0, t_step=0.05), duration=0.15)
    smooth = simulate(
        lp, Step(amplitude=100.0, offset=20.0, t_step=0.05, rise_time=0.01), duration=0.15
    )
    assert sharp.u.max() > 400.0 and smooth.u.max() < 150.0
    assert sharp.stable and smooth.stable


def test_delay_option_runs_and_costs_little(experiment):
    a = simulate(loop(experiment), SINE, duration=2.0)
    b = simulate(loop(experiment, delay=True), SINE, duration=2.0)
    c = simulate(loop(experiment, delay=True, compensate_delay=False), SINE, duration=2.0)
    assert a.stable and b.stable and c.stable
    assert b.metrics.me < 0.05 and c.metrics.me > b.metrics.me


def test_mismatch_is_used(experiment):
    tp = experiment.replace(a3=experiment.a3 * 0.98)
    a = simulate(loop(experiment, "eso"), SINE, duration=2.0)
    b = simulate(loop(experiment, "eso"), SINE, duration=2.0, true_params=tp)
    assert b.metrics.me > a.metrics.me
    assert b.settings["true_plant"]["a3"] == tp.a3


def test_result_is_frozen_and_serialisable(experiment):
    r = simulate(loop(experiment, "eso"), SINE, duration=0.1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.stable = False
    with pytest.raises(ValueError):
        r.u[0] = 1.0
    doc = r.to_dict(series=True)
    text = json.dumps(json_safe(doc))
    assert set(doc["metrics"]) == {"maxe", "me", "rmse"}
    assert set(doc["estimation_rmse"]) == {"x1", "x2", "x3"}
    assert len(json.loads(text)["series"]["t"]) == r.t.size


def test_plot(experiment):
    r = simulate(loop(experiment, "eso"), SINE, duration=0.1)
    fig, axes = r.plot(title="t")
    assert axes.shape == (4, 1) and fig.axes


def test_observer_object_and_factory(experiment):
    obs = HysteresisObserver(experiment, FAST, DT)
    x_before = obs.x.copy()
    custom = loop(experiment).replace(observer=ObserverSpec.from_custom(obs))
    a = simulate(custom, SINE, duration=0.2)
    np.testing.assert_array_equal(obs.x, x_before)  # the caller's object is not advanced
    assert a.settings["path"] == "generic"  # a custom observer runs its own methods
    b = simulate(loop(experiment), SINE, duration=0.2)
    np.testing.assert_allclose(a.x, b.x, atol=1e-9)
    factory = ObserverSpec.from_custom(lambda p, dt: HysteresisObserver(p, FAST, dt))
    c = simulate(loop(experiment).replace(observer=factory), SINE, duration=0.2)
    np.testing.assert_allclose(c.x, b.x, atol=1e-9)


def test_ukf_plugs_in(experiment):
    r = simulate(loop(experiment, "ukf"), SINE, duration=0.15, noise_std=0.02)
    assert r.stable and r.settings["observer"] == "ukf"


def test_controller_object_is_not_mutated(experiment):
    c = DiscreteTrackingController(experiment, 240.0, 240.0, dt=DT, integral_rate=120.0)
    a = simulate(loop(experiment, controller=c), SINE, duration=0.2)
    assert c.q == 0.0
    b = simulate(loop(experiment, controller=c), SINE, duration=0.2)
    np.testing.assert_array_equal(a.u, b.u)


def continuous_loop(p, observer, **kw):
    """``observer`` on FAST with eq. (12) at lambda1 = lambda2 = 200 1/s, continuous form."""
    return ClosedLoop(p, ObserverSpec.of(observer, FAST), make_controller(p, 200.0, 200.0), **kw)


def test_continuous_path_matches_fine_sampling(experiment):
    """The continuous loop and the sampled loop at a 20x finer step agree (ESO)."""
    ref = Sine(amplitude=20.0, offset=30.0, frequency=5.0)
    lp = continuous_loop(experiment, "eso")
    c = simulate_continuous(lp, ref, duration=0.5, solver=ContinuousSolver(output_dt=1e-4))
    s = simulate(lp.replace(dt=1e-5), ref, duration=0.5)
    assert c.stable and c.mode == "continuous"
    assert c.metrics.me == pytest.approx(s.metrics.me, rel=0.1)
    assert c.metrics.maxe == pytest.approx(s.metrics.maxe, rel=0.1)


def test_continuous_phso_is_exact(experiment):
    ref = Triangle(amplitude=20.0, offset=30.0, frequency=5.0)
    r = simulate_continuous(
        continuous_loop(experiment, "phso"),
        ref,
        duration=0.5,
        solver=ContinuousSolver(output_dt=1e-4),
    )
    assert r.stable and r.settings["udot"] == "implicit"
    assert r.estimation_rmse[2] < 1e-9  # same model, same u': no estimation error
    # the error is the corners' (x_d' jumps, the x_d'' impulse is dropped), gone mid-leg:
    # critically damped at 200 1/s, (1 + 10) exp(-10) of a ~1.5 um spike after 50 ms
    # corners (phase 0) at 0.05 + 0.1 n s, mid-legs at 0.1 n s
    mid = (np.abs(r.t / 0.1 - np.round(r.t / 0.1)) < 1e-6) & (r.t > 0.15)
    assert mid.sum() >= 3 and np.max(np.abs(r.e[mid])) < 5e-3
    assert 0.5 < r.metrics.maxe < 3.0


def test_implicit_udot_relation(experiment):
    p = experiment
    c = p.a1 / p.a3
    for A, h in [(300.0, 0.5), (-250.0, -0.9), (10.0, 1.1), (0.0, 0.3)]:
        v = _solve_udot(A, c, p, h)
        s = 1.0 if v >= 0 else -1.0
        kappa = p.alpha - p.beta * s * h - p.gamma * abs(h)
        assert v == pytest.approx(A + c * kappa * v, abs=1e-9)
    with pytest.raises(InputError, match="ill-posed"):
        _solve_udot(-1.0, c, p, 10.0)  # c dh/du >= 1 far outside the hysteresis range


def test_continuous_rejects_unbounded(simulation):
    from bwdesign import preset

    unbounded = preset("paper_simulation")
    spec, law = ObserverSpec.of("phso", (80, 160, -640)), make_controller(simulation, 1.0, 2.0)
    with pytest.raises(UnboundedModelError):  # as the loop's model
        ClosedLoop(unbounded, spec, make_controller(unbounded, 1.0, 2.0))
    with pytest.raises(UnboundedModelError):  # as the simulated plant
        simulate_continuous(
            ClosedLoop(simulation, spec, law), SINE, duration=0.1, true_params=unbounded
        )


def test_continuous_refuses_what_it_does_not_run(experiment):
    """The continuous loop runs the PHSO or the ESO with eq. (12) in continuous form."""
    lp = continuous_loop(experiment, "eso")
    for bad, match in [
        (lp.replace(observer=ObserverSpec.of("phdo", FAST)), "'phso' or 'eso'"),
        (lp.replace(controller=make_controller(experiment, 200.0, 200.0, form="discrete",
                                               dt=DT), dt=DT), "continuous form"),
    ]:  # fmt: skip
        with pytest.raises(InputError, match=match):
            simulate_continuous(bad, SINE, duration=0.1)
    with pytest.raises(InputError, match="solver must be a ContinuousSolver"):
        simulate_continuous(lp, SINE, duration=0.1, solver="Radau")


SOLVER_BAD = [
    ("method", dict(method="RK45"), "stiff solver"),
    ("rtol", dict(rtol=0.0), "rtol"),
    ("atol", dict(atol=-1.0), "atol"),
    ("max_step", dict(max_step=0.0), "max_step"),
    ("amplifier_bandwidth", dict(amplifier_bandwidth=-5.0), "amplifier_bandwidth"),
]


@pytest.mark.parametrize("label, kw, match", SOLVER_BAD, ids=[b[0] for b in SOLVER_BAD])
def test_continuous_solver_refuses(label, kw, match):
    with pytest.raises(InputError, match=match):
        ContinuousSolver(**kw)


def _spec(kind="phso", gains=FAST):
    return ObserverSpec.of(kind, gains)


#: One row per check of a loop and a run: the old keyword API's checks, now on the
#: types that hold them (ClosedLoop, ObserverSpec, Start, make_controller) or on simulate.
BAD = [
    ("short run", lambda p: simulate(loop(p), SINE, duration=DT), InputError,
     "fewer than 2 samples"),
    ("negative noise", lambda p: simulate(loop(p), SINE, duration=0.1, noise_std=-1.0),
     InputError, "noise_std"),
    ("float seed", lambda p: simulate(loop(p), SINE, duration=0.1, seed=1.5), InputError,
     "seed must be an integer"),
    ("not a loop", lambda p: simulate(p, SINE, duration=0.1), InputError,
     "loop must be a ClosedLoop"),
    ("unknown observer", lambda p: _spec("kalman"), InputError, "observer must be"),
    ("missing gains", lambda p: _spec("phso", None), InputError, "needs observer gains"),
    ("PHDO on 3 gains without .of", lambda p: ObserverSpec("phdo", FAST), GainError,
     "takes 4 gains"),
    ("gains for the UKF", lambda p: _spec("ukf"), InputError, "takes no gains"),
    ("custom without predict", lambda p: ObserverSpec.from_custom(object()), InputError,
     "predict"),
    ("unstable gains", lambda p: loop(p, gains=(8.0, 64.0, 512.0)), GainError, "l3"),
    ("no controller", lambda p: ClosedLoop(p, _spec(), None, dt=DT), InputError,
     "controller must be a TrackingController"),
    ("no lambda1", lambda p: make_controller(p, None, 200.0), GainError, "lambda1"),
    ("negative lambda", lambda p: make_controller(p, -1.0, 200.0), GainError, "lambda1"),
    ("controller for another dt", lambda p: loop(p).replace(dt=1e-4), InputError,
     "built for dt = 0.0002 s"),
    ("jump with ESO", lambda p: loop(p, "eso", controller=tuned(p, hysteresis_jump=True)),
     InputError, "PHSO"),
    ("bad x0", lambda p: Start(x0=(1.0, 2.0)), InputError, "x0"),
    ("bad u_prev", lambda p: Start(u_prev=math.nan), InputError, "u_prev"),
    ("bad start", lambda p: loop(p, start="rest"), InputError, "start must be a Start"),
    ("bad dt", lambda p: ClosedLoop(p, _spec(), make_controller(p, 200.0, 200.0), dt=0.0),
     InputError, "dt"),
    ("bad divergence limit", lambda p: loop(p, divergence_limit=0.0), InputError,
     "divergence_limit"),
    ("bad limits", lambda p: make_controller(p, 200.0, 200.0, u_limits=(5.0, 1.0)),
     InputError, "u_min < u_max"),
]  # fmt: skip


@pytest.mark.parametrize("label, build, err, match", BAD, ids=[b[0] for b in BAD])
def test_bad_inputs(experiment, label, build, err, match):
    with pytest.raises(err, match=match):
        build(experiment)


def test_bad_reference(experiment):
    with pytest.raises(InputError, match="reference"):
        simulate(loop(experiment), "sine", duration=0.1)


# -- command line ------------------------------------------------------------------

CLI_OK = [
    "simulate", "--plant", "paper_experiment", "--amplitude", "80", "--offset", "100",
    "--frequency", "1", "--gains", "2286.2,1208280,-6256.75", "--lambda1", "240",
    "--lambda2", "240", "--form", "discrete", "--dt", "2e-4", "--duration", "0.5",
]  # fmt: skip


def test_cli_json_and_csv(tmp_path, capsys):
    csv = tmp_path / "run.csv"
    code = main([*CLI_OK, "--noise-std", "0.01", "--seed", "3", "--json", "--csv", str(csv)])
    out, err = capsys.readouterr()
    assert code == 0 and err == ""
    doc = json.loads(out)
    assert set(doc["metrics"]) == {"maxe", "me", "rmse"}
    assert doc["length_unit"] == "um" and len(doc["window"]) == 2
    assert set(doc["estimation_rmse"]) == {"x1", "x2", "x3"}
    assert doc["settings"]["noise_std"] == 0.01 and doc["settings"]["seed"] == 3
    data = np.loadtxt(csv, delimiter=",", skiprows=2)  # signature line, header
    assert data.shape == (2500, 11)
    assert csv.read_text().splitlines()[1] == "t,x1,x2,x3,x1hat,x2hat,x3hat,u,x_d,e,z"
    assert not list(tmp_path.glob(".bwdesign-*"))  # no temporary left behind


def test_cli_text_output(capsys):
    code = main(CLI_OK)
    out, _ = capsys.readouterr()
    assert code == 0 and "MAXE" in out and "ME " in out and "RMSE" in out


def test_cli_unstable_is_exit_1(capsys):
    argv = [a if a != "240" else "2.2e6" for a in CLI_OK]
    code = main([*argv, "--form", "continuous", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 1 and doc["stable"] is False


CLI_BAD = [
    ("malformed gains", ["--gains", "1,2"], "comma-separated gains l1,l2,l3"),
    ("negative dt", ["--dt", "-1"], "--dt"),
    ("zero duration", ["--duration", "0"], "--duration"),
    ("negative noise", ["--noise-std", "-0.1"], "--noise-std"),
    ("non-numeric lambda", ["--lambda1", "fast"], "--lambda1"),
    ("unknown observer", ["--observer", "kf"], "invalid choice"),
    ("unknown reference", ["--reference", "saw"], "invalid choice"),
    ("bad seed", ["--seed", "x"], "--seed"),
    ("frequency for a step", ["--reference", "step"], "does not apply"),
    ("one limit only", ["--u-min", "-10"], "both --u-min and --u-max"),
    ("too many samples", ["--dt", "1e-9", "--duration", "100"], "exceeds the limit"),
    ("unknown plant", ["--plant", "nope"], "unknown plant preset"),
    ("unstable observer gains", ["--gains", "8,64,512"], "l3"),
    ("integral without discrete", ["--form", "continuous", "--integral-rate", "5"], "discrete"),
    ("missing csv dir", ["--csv", "/nonexistent-dir/x.csv"], "does not exist"),
]


@pytest.mark.parametrize("label, extra, message", CLI_BAD, ids=[b[0] for b in CLI_BAD])
def test_cli_bad_flags(tmp_path, capsys, label, extra, message):
    csv = tmp_path / "out.csv"
    argv = [*CLI_OK, "--csv", str(csv), *extra]
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ")
    assert message in lines[0]
    assert not csv.exists() and not list(tmp_path.iterdir())  # nothing written


def test_cli_help_lists_simulate(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "simulate" in capsys.readouterr().out
    assert math.isfinite(1.0)
