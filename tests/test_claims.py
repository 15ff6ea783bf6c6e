"""Issue 19: every claim checked. One section per item of the issue (2-8).

Each test here failed on the commit the issue was filed against (16f545d).
"""

import numpy as np
import pytest

from bwdesign import (
    ExtendedStateObserver,
    HysteresisObserver,
    UnscentedObserver,
    preset,
)
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
