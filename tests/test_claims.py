"""Issue 19: every claim checked. One section per item of the issue (2-8).

Each test here failed on the commit the issue was filed against (16f545d).
"""

import json
from pathlib import Path

import numpy as np
import pytest

from bwdesign import (
    ExtendedStateObserver,
    HysteresisObserver,
    UnscentedObserver,
    preset,
)
from bwdesign.cli.main import main
from bwdesign.errors import GainError, InputError

P = preset("paper_experiment")
G = (8.0, 64.0, -512.0)


def _phso():
    return HysteresisObserver(P, G, 2e-4)


def _eso():
    return ExtendedStateObserver(P, G, 2e-4)


def _ukf():
    return UnscentedObserver(P, 2e-4, udot_max=400.0)


OBSERVERS = [_phso, _eso, _ukf]
IDS = ["phso", "eso", "ukf"]


# -- item 8: the observers' Python API -----------------------------------------


@pytest.mark.parametrize("make", OBSERVERS, ids=IDS)
@pytest.mark.parametrize(
    "u", [np.int64(3), np.float32(2.5), np.float64(1.0), 4, 2.0, np.array([1.5])]
)
def test_numbers_real_are_accepted(make, u):
    obs = make()
    obs.predict(u)
    obs.update(np.int64(0))
    assert obs.x.shape == (3,) and np.all(np.isfinite(obs.x))


def test_numpy_integers_in_constructors():
    UnscentedObserver(P, np.float64(2e-4), udot_max=np.int64(361), noise_std=np.float32(0.01))
    HysteresisObserver(P, np.array([8, 64, -512], dtype=np.int64), np.float64(2e-4))


@pytest.mark.parametrize("make", OBSERVERS, ids=IDS)
@pytest.mark.parametrize(
    "call, match",
    [
        (lambda o: o.predict(None), "u must be a number, got NoneType"),
        (lambda o: o.predict("1.0"), "u must be a number, got str"),
        (lambda o: o.predict(True), "boolean"),
        (lambda o: o.predict(np.bool_(True)), "boolean"),
        (lambda o: o.update(True), "boolean"),
        (lambda o: o.update("0.0"), "z must be a number, got str"),
        (lambda o: o.batch_filter(None, [1.0, 2.0]), "zs must be a sequence"),
        (lambda o: o.batch_filter([0.0, 0.0], None), "us must be a 1-D sequence of numbers"),
        (lambda o: o.batch_filter([0.0, 0.0], ["1", "2"]), "us must be a 1-D sequence of numbers"),
        (lambda o: o.batch_filter([True, 0.0], [1.0, 2.0]), "boolean"),
    ],
    ids=[
        "predict-None",
        "predict-str",
        "predict-bool",
        "predict-np-bool",
        "update-bool",
        "update-str",
        "batch-zs-None",
        "batch-us-None",
        "batch-us-str",
        "batch-zs-bool",
    ],
)
def test_misuse_raises_input_error(make, call, match):
    obs = make()
    x = obs.x.copy()
    with pytest.raises(InputError, match=match):
        call(obs)
    np.testing.assert_array_equal(obs.x, x)  # nothing ran


@pytest.mark.parametrize(
    "build",
    [
        lambda: HysteresisObserver("paper_experiment", G, 2e-4),
        lambda: ExtendedStateObserver("paper_experiment", G, 2e-4),
        lambda: UnscentedObserver("paper_experiment", 2e-4, udot_max=400.0),
    ],
    ids=IDS,
)
def test_preset_name_as_params_is_a_typed_error(build):
    with pytest.raises(InputError, match=r"params must be a BoucWenParams .*bwdesign.preset"):
        build()


@pytest.mark.parametrize("gains", [("8", "64", "-512"), (True, 64, -512), None])
def test_gains_must_be_numbers(gains):
    with pytest.raises(GainError):
        HysteresisObserver(P, gains, 2e-4)


@pytest.mark.parametrize("make", OBSERVERS, ids=IDS)
def test_state_assignment_accepts_3_and_3x1(make):
    obs = make()
    obs.x = np.array([[1.0], [2.0], [0.5]])  # filterpy-style column
    assert obs.x.shape == (3,)
    np.testing.assert_array_equal(obs.x, [1.0, 2.0, 0.5])
    obs.predict(1.0)
    obs.update(1.0)
    obs.x = [0.0, 0.0, 0.0]
    assert obs.x.shape == (3,)
    for bad in ([1.0, 2.0], np.zeros((1, 3)), ["a", "b", "c"], None):
        with pytest.raises(InputError, match="x must be three finite numbers"):
            obs.x = bad


@pytest.mark.parametrize("make", OBSERVERS, ids=IDS)
def test_non_finite_state_is_refused_identically(make):
    obs = make()
    with pytest.raises(InputError, match=r"^x must be finite, got \[nan, 0.0, 0.0\]$"):
        obs.x = [np.nan, 0.0, 0.0]
    with pytest.raises(InputError, match="x0 must be finite"):
        obs.reset([0.0, np.inf, 0.0])
    # a NaN written in place is caught before it spreads
    obs.x[0] = np.nan
    with pytest.raises(InputError, match="the estimate x = .* is not finite; reset"):
        obs.predict(1.0)
    with pytest.raises(InputError, match="the estimate x = .* is not finite; reset"):
        obs.update(0.0)
    with pytest.raises(InputError, match="the estimate x = .* is not finite; reset"):
        obs.batch_filter([0.0], [1.0])


@pytest.mark.parametrize(
    "start, kw",
    [
        (dict(u_prev="1.0"), {}),
        (dict(u_prev=True), {}),
        ({}, dict(duration="0.2")),
        ({}, dict(noise_std=None)),
    ],
)
def test_simulate_refuses_strings_and_booleans(start, kw):
    from bwdesign import ClosedLoop, ObserverSpec, Sine, Start, make_controller, simulate

    with pytest.raises(InputError, match="must be a number"):
        loop = ClosedLoop(
            P,
            ObserverSpec.of("phso", G),
            make_controller(P, 1.0, 2.0),
            dt=2e-4,
            start=Start(**start),
        )
        simulate(loop, Sine(amplitude=10, offset=10, frequency=5), **{"duration": 0.2, **kw})


def test_ukf_interface_matches_or_says_what_differs():
    obs = _ukf()
    assert obs.gains is None
    np.testing.assert_array_equal(obs.K, np.zeros(3))
    obs.predict(1.0)
    obs.update(0.01)
    assert obs.K.shape == (3,) and np.all(np.isfinite(obs.K)) and obs.K[0] > 0
    with pytest.raises(GainError, match="no continuous form"):
        obs.as_iosystem()
    for o in (_phso(), _eso()):
        assert o.K.shape == (3,) and o.gains is not None
        o.as_iosystem()


# -- item 6: no silent options ---------------------------------------------------


ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "paper_experiment.toml"
SIM = ["simulate", "--plant", "paper_experiment", "--amplitude", "80", "--offset", "100"]
SIM += ["--frequency", "1", "--lambda1", "1", "--lambda2", "2", "--dt", "2e-4"]
SIM += ["--duration", "0.2"]


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--observer", "ukf", "--gains", "8,64,-512"], "--gains does not apply to --observer ukf"),
        (["--gains", "8,64,-512", "--udot-max", "400"], "--udot-max applies to --observer ukf"),
    ],
    ids=["ukf-gains", "phso-udot-max"],
)
def test_options_that_do_not_apply_are_errors(capsys, extra, message):
    code, out, err = _run(SIM + extra, capsys)
    assert code == 2 and out == ""
    assert err.startswith("error: ") and len(err.splitlines()) == 1 and message in err


def test_ukf_step_has_a_udot_max_path(capsys):
    argv = ["simulate", "--plant", "paper_experiment", "--reference", "step"]
    argv += ["--amplitude", "10", "--observer", "ukf", "--lambda1", "1", "--lambda2", "2"]
    argv += ["--dt", "2e-4", "--duration", "0.2", "--json"]
    code, _, err = _run(argv, capsys)
    assert code == 2 and "--udot-max" in err  # the error names the option that fixes it
    code, out, err = _run(argv + ["--udot-max", "400"], capsys)
    assert code == 0 and err == ""
    assert json.loads(out)["settings"]["observer"] == "ukf"


def test_negative_gain_lists_read_as_written(capsys):
    spaced = _run(SIM + ["--gains", "-8,64,-512", "--json"], capsys)
    joined = _run(SIM + ["--gains=-8,64,-512", "--json"], capsys)
    assert spaced[0] == 0 and spaced[2] == ""
    assert json.loads(spaced[1])["settings"]["gains"] == [-8.0, 64.0, -512.0]
    assert json.loads(spaced[1])["metrics"] == json.loads(joined[1])["metrics"]
    code, out, _ = _run(
        ["certify", "--plant", "paper_experiment", "--gains", "-8,64,-512", "--udot-max", "361e0"],
        capsys,
    )
    assert code == 0 and "gains l = (-8, 64, -512)" in out


def test_stage_file_sections_are_defaults_and_said(capsys):
    """--plant FILE.toml: the file's sections fill the options not given, and say so."""
    code, out, err = _run(
        ["simulate", "--plant", str(CONFIG), "--duration", "0.2", "--json"], capsys
    )
    assert code == 0 and err == ""
    doc = json.loads(out)
    s = doc["settings"]
    assert s["gains"] == [8.0, 64.0, -512.0] and s["dt"] == 2e-4
    assert s["controller"]["lambda1"] == 1.0 and doc["reference"]["amplitude"] == 80.0
    used = doc["defaults_from_file"]["options"]
    assert used == {
        "--gains": "[observer]",
        "--dt": "[sampling]",
        "--lambda1": "[controller]",
        "--lambda2": "[controller]",
        "--reference": "[reference]",
    }
    # an option on the command line wins, and is not reported as taken from the file
    code, out, _ = _run(
        ["simulate", "--plant", str(CONFIG), "--duration", "0.2", "--lambda1", "3", "--json"],
        capsys,
    )
    doc = json.loads(out)
    assert doc["settings"]["controller"]["lambda1"] == 3.0
    assert "--lambda1" not in doc["defaults_from_file"]["options"]
    code, out, _ = _run(["certify", "--plant", str(CONFIG)], capsys)
    assert code == 0
    assert out.splitlines()[0] == (
        f"from {CONFIG}: --gains ([observer]), --udot-max ([envelope]), --dt ([sampling])"
    )
    assert "dt = 0.0002 s" in out


# -- item 7: one vocabulary (the text printed around the certificates) ------------


def test_error_line_names_the_file_once(tmp_path, capsys):
    f = tmp_path / "noplant.toml"
    f.write_text("[observer]\ngains = [1.0, 2.0, 3.0]\n")
    code, out, err = _run(
        ["certify", "--plant", str(f), "--gains", "8,64,-512", "--udot-max", "361"], capsys
    )
    assert code == 2 and out == ""
    assert err == f"error: {f}: missing required section [plant]\n"


def test_capped_rate_text_matches_the_data(capsys):
    """With exact envelopes no rate search stops at a limit: no "+" mark, no legend for it,
    and a tier that does not hold says so at the requested rate (issue 19 item 7)."""
    from bwdesign import certify

    rep = certify(P, (2468.378, 586392.0, -941.6449), udot_max=1e8, dt=2e-4)
    assert not any(c.max_udot_capped for c in rep.certificates)
    code, out, _ = _run(
        ["certify", "--plant", "paper_experiment", "--gains", "2468.378,586392,-941.6449"]
        + ["--udot-max", "1e8", "--dt", "2e-4"],
        capsys,
    )
    assert "+" not in out.split("tier", 1)[1].split("certified:")[0].replace("e+", "")
    assert "the tier may hold for every rate" not in out
    for c in rep.certificates:
        row = next(x for x in out.splitlines() if x.startswith(c.name))
        assert ("yes" if c.holds else "no") in row.split()[1]
