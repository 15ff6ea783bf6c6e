"""Closed-loop simulation: sampled and continuous paths, options, CLI."""

import dataclasses
import json
import math

import numpy as np
import pytest

from bwdesign import (
    DiscreteTrackingController,
    HysteresisObserver,
    Sine,
    Step,
    Triangle,
    simulate,
    simulate_continuous,
)
from bwdesign.cli.main import main
from bwdesign.control.tuning import observer_gains
from bwdesign.errors import GainError, InputError, UnboundedModelError
from bwdesign.output.jsonenc import json_safe
from bwdesign.sim.continuous import _solve_udot
from bwdesign.sim.metrics import steady_state_window

DT = 2e-4
SINE = Sine(amplitude=80.0, offset=100.0, frequency=1.0)
FAST = (2286.2, 1208280.0, -6256.75)  # triple observer pole at 1000 rad/s on paper_experiment
TUNED = dict(gains=FAST, lambda1=240.0, lambda2=240.0, form="discrete", integral_rate=120.0)


def test_tracking_error_decays(experiment):
    r = simulate(experiment, SINE, dt=DT, duration=2.0, observer="phso", **TUNED)
    assert r.stable and r.status == "ok"
    assert abs(r.e[0]) == pytest.approx(100.0)  # starts at rest at 0, reference at 100
    assert r.metrics.maxe < 0.05 and r.metrics.me < 0.01
    assert r.window == steady_state_window(r.t, SINE.period)
    assert np.max(np.abs(r.e[r.t > 1.0])) < 1e-3 * np.max(np.abs(r.e[r.t < 0.05]))
    assert r.estimation_rmse[0] < 1e-6  # exact model, exact initial estimate


def test_phso_beats_eso_nominal(experiment):
    res = {
        o: simulate(experiment, SINE, dt=DT, duration=3.0, observer=o, **TUNED)
        for o in ("phso", "eso")
    }
    assert res["phso"].metrics.me < res["eso"].metrics.me
    assert res["phso"].metrics.rmse < res["eso"].metrics.rmse
    assert res["phso"].estimation_rmse[2] < res["eso"].estimation_rmse[2]


def test_fast_path_equals_generic_path(experiment):
    """The scalar-inlined runner and the object runner give the same record."""
    tp = experiment.replace(a1=experiment.a1 * 1.01)
    for obs in ("phso", "eso"):
        for delay, comp in ((False, True), (True, True), (True, False)):
            kw = dict(
                dt=DT,
                duration=0.3,
                observer=obs,
                noise_std=0.02,
                seed=4,
                delay=delay,
                compensate_delay=comp,
                true_params=tp,
                u_limits=(-30.0, 150.0),
                estimate_limits=((-50.0, 250.0), None, (-5.0, 5.0)),
                **TUNED,
            )
            a = simulate(experiment, SINE, fast=True, **kw)
            b = simulate(experiment, SINE, fast=False, **kw)
            assert a.settings["path"] == "fast" and b.settings["path"] == "generic"
            np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9)
            np.testing.assert_allclose(a.u, b.u, rtol=0, atol=1e-9)
            np.testing.assert_allclose(a.xhat, b.xhat, rtol=0, atol=1e-9)


def test_hysteresis_jump_fast_equals_generic(experiment):
    kw = dict(dt=DT, duration=0.2, observer="phso", hysteresis_jump=True, **TUNED)
    a = simulate(experiment, SINE, **kw)
    b = simulate(experiment, SINE, fast=False, **kw)
    np.testing.assert_allclose(a.u, b.u, atol=1e-9)


def test_noise_is_seeded(experiment):
    kw = dict(dt=DT, duration=0.2, observer="eso", noise_std=0.02, **TUNED)
    a = simulate(experiment, SINE, seed=7, **kw)
    b = simulate(experiment, SINE, seed=7, **kw)
    c = simulate(experiment, SINE, seed=8, **kw)
    np.testing.assert_array_equal(a.z, b.z)
    assert not np.array_equal(a.z, c.z)
    assert np.std(a.z - a.x[:, 0]) == pytest.approx(0.02, rel=0.1)


def test_divergence_is_reported_not_raised(experiment):
    """Eq. (12) with the Section 4.2 lambda1 = 2.2e6 sampled at 0.2 ms blows up."""
    r = simulate(
        experiment,
        SINE,
        dt=DT,
        duration=1.0,
        observer="phso",
        gains=(8.0, 64.0, -512.0),
        lambda1=2.2e6,
        lambda2=80.0,
    )
    assert not r.stable and r.metrics is None and r.estimation_rmse is None
    assert r.status.startswith("diverged at t = ")
    assert r.t.size < 5000 and np.all(np.isfinite(r.x))
    doc = r.to_dict()
    assert doc["stable"] is False and doc["metrics"] is None
    json.dumps(json_safe(doc))


def test_input_limits_hold_and_drive_the_observer(experiment):
    r = simulate(
        experiment,
        Step(amplitude=100.0, offset=20.0, t_step=0.02),
        dt=DT,
        duration=0.1,
        observer="phso",
        u_limits=(-30.0, 60.0),
        **TUNED,
    )
    assert r.u.max() <= 60.0 and r.u.min() >= -30.0
    assert r.saturated_fraction > 0
    # the observer saw the clipped input: its estimate stays exact
    assert np.max(np.abs(r.xhat - r.x)) < 1e-6


def test_smoothed_step_removes_the_input_peak(experiment):
    """The peaking remedy: a quintic rise instead of a sharp step."""
    g = tuple(observer_gains(experiment, [-5000.0] * 3))
    kw = dict(dt=DT, duration=0.15, observer="eso", gains=g, lambda1=1000.0, lambda2=1000.0,
              form="discrete", x0=(20.0, 0.0, 0.0), xhat0=(20.0, 0.0, 0.0),
              u_prev=20.0 * experiment.a1 / experiment.a3)  # fmt: skip
    sharp = simulate(experiment, Step(amplitude=100.0, offset=20.0, t_step=0.05), **kw)
    smooth = simulate(
        experiment, Step(amplitude=100.0, offset=20.0, t_step=0.05, rise_time=0.01), **kw
    )
    assert sharp.u.max() > 400.0 and smooth.u.max() < 150.0
    assert sharp.stable and smooth.stable


def test_delay_option_runs_and_costs_little(experiment):
    a = simulate(experiment, SINE, dt=DT, duration=2.0, observer="phso", **TUNED)
    b = simulate(experiment, SINE, dt=DT, duration=2.0, observer="phso", delay=True, **TUNED)
    c = simulate(
        experiment,
        SINE,
        dt=DT,
        duration=2.0,
        observer="phso",
        delay=True,
        compensate_delay=False,
        **TUNED,
    )
    assert a.stable and b.stable and c.stable
    assert b.metrics.me < 0.05 and c.metrics.me > b.metrics.me


def test_mismatch_is_used(experiment):
    tp = experiment.replace(a3=experiment.a3 * 0.98)
    a = simulate(experiment, SINE, dt=DT, duration=2.0, observer="eso", **TUNED)
    b = simulate(experiment, SINE, dt=DT, duration=2.0, observer="eso", true_params=tp, **TUNED)
    assert b.metrics.me > a.metrics.me
    assert b.settings["true_plant"]["a3"] == tp.a3


def test_result_is_frozen_and_serialisable(experiment):
    r = simulate(experiment, SINE, dt=DT, duration=0.1, observer="eso", **TUNED)
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
    r = simulate(experiment, SINE, dt=DT, duration=0.1, observer="eso", **TUNED)
    fig, axes = r.plot(title="t")
    assert axes.shape == (4, 1) and fig.axes


def test_observer_object_and_factory(experiment):
    obs = HysteresisObserver(experiment, FAST, DT)
    x_before = obs.x.copy()
    a = simulate(experiment, SINE, dt=DT, duration=0.2, observer=obs, **TUNED)
    np.testing.assert_array_equal(obs.x, x_before)  # the caller's object is not advanced
    b = simulate(experiment, SINE, dt=DT, duration=0.2, observer="phso", **TUNED)
    np.testing.assert_allclose(a.x, b.x, atol=1e-9)
    c = simulate(
        experiment,
        SINE,
        dt=DT,
        duration=0.2,
        observer=lambda p, dt: HysteresisObserver(p, FAST, dt),
        **{k: v for k, v in TUNED.items() if k != "gains"},
    )
    np.testing.assert_allclose(c.x, b.x, atol=1e-9)


def test_ukf_plugs_in(experiment):
    r = simulate(
        experiment,
        SINE,
        dt=DT,
        duration=0.15,
        observer="ukf",
        noise_std=0.02,
        **{k: v for k, v in TUNED.items() if k != "gains"},
    )
    assert r.stable and r.settings["observer"] == "ukf"


def test_controller_object_is_not_mutated(experiment):
    c = DiscreteTrackingController(experiment, 240.0, 240.0, dt=DT, integral_rate=120.0)
    a = simulate(experiment, SINE, dt=DT, duration=0.2, observer="phso", gains=FAST, controller=c)
    assert c.q == 0.0
    b = simulate(experiment, SINE, dt=DT, duration=0.2, observer="phso", gains=FAST, controller=c)
    np.testing.assert_array_equal(a.u, b.u)


def test_continuous_path_matches_fine_sampling(experiment):
    """The continuous loop and the sampled loop at a 20x finer step agree (ESO)."""
    ref = Sine(amplitude=20.0, offset=30.0, frequency=5.0)
    kw = dict(gains=FAST, lambda1=200.0, lambda2=200.0)
    c = simulate_continuous(experiment, ref, duration=0.5, observer="eso", output_dt=1e-4, **kw)
    s = simulate(experiment, ref, dt=1e-5, duration=0.5, observer="eso", **kw)
    assert c.stable and c.mode == "continuous"
    assert c.metrics.me == pytest.approx(s.metrics.me, rel=0.1)
    assert c.metrics.maxe == pytest.approx(s.metrics.maxe, rel=0.1)


def test_continuous_phso_is_exact(experiment):
    ref = Triangle(amplitude=20.0, offset=30.0, frequency=5.0)
    r = simulate_continuous(
        experiment,
        ref,
        duration=0.5,
        observer="phso",
        gains=FAST,
        lambda1=200.0,
        lambda2=200.0,
        output_dt=1e-4,
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

    with pytest.raises(UnboundedModelError):
        simulate_continuous(
            preset("paper_simulation"),
            SINE,
            duration=0.1,
            gains=(80, 160, -640),
            lambda1=1.0,
            lambda2=2.0,
        )


BAD = [
    ("short run", dict(duration=DT), InputError, "fewer than 2 samples"),
    ("negative noise", dict(noise_std=-1.0), InputError, "noise_std"),
    ("float seed", dict(seed=1.5), InputError, "seed must be an integer"),
    ("unknown observer", dict(observer="kalman"), InputError, "observer must be"),
    ("missing gains", dict(gains=None), InputError, "needs observer gains"),
    ("unstable gains", dict(gains=(8.0, 64.0, 512.0)), GainError, "l3"),
    ("no lambdas", dict(lambda1=None), InputError, "lambda1 and lambda2"),
    ("negative lambda", dict(lambda1=-1.0), GainError, "lambda1"),
    ("jump with ESO", dict(observer="eso", hysteresis_jump=True), InputError, "PHSO"),
    ("bad x0", dict(x0=(1.0, 2.0)), InputError, "x0"),
    ("bad dt", dict(dt=0.0), InputError, "dt"),
    ("bad limits", dict(u_limits=(5.0, 1.0)), InputError, "u_min < u_max"),
]


@pytest.mark.parametrize("label, kw, err, match", BAD, ids=[b[0] for b in BAD])
def test_bad_inputs(experiment, label, kw, err, match):
    args = dict(dt=DT, duration=0.1, observer="phso", gains=FAST, lambda1=200.0, lambda2=200.0)
    args.update(kw)
    with pytest.raises(err, match=match):
        simulate(experiment, SINE, **args)


def test_bad_reference(experiment):
    with pytest.raises(InputError, match="reference"):
        simulate(experiment, "sine", dt=DT, duration=0.1, gains=FAST, lambda1=1.0, lambda2=2.0)


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
