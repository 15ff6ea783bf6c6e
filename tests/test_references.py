import math

import numpy as np
import pytest

from bwdesign import ConfigError, Sine, Step, Triangle
from bwdesign.model.references import reference_from_dict


def _num_derivative(f, t, h=1e-6):
    return (f(t + h) - f(t - h)) / (2 * h)


REFS = [
    Sine(amplitude=80.0, offset=100.0, frequency=1.0),
    Sine(amplitude=30.0, offset=30.0, frequency=20.0, phase=-0.5 * math.pi),
    Triangle(amplitude=90.0, offset=100.0, frequency=1.0, corner_time=0.02),
    Step(amplitude=50.0, offset=10.0, t_step=0.1, rise_time=0.05),
]


@pytest.mark.parametrize("ref", REFS, ids=lambda r: r.describe())
def test_derivatives_are_consistent(ref):
    t = np.linspace(0.013, 1.97, 3001)
    xd, v, a = ref.evaluate(t)
    np.testing.assert_allclose(
        v, _num_derivative(lambda s: ref.evaluate(s)[0], t), atol=1e-5 * (1 + np.abs(v).max())
    )
    np.testing.assert_allclose(
        a, _num_derivative(lambda s: ref.evaluate(s)[1], t), atol=1e-4 * (1 + np.abs(a).max())
    )


def test_sine_matches_formula():
    r = Sine(amplitude=80.0, offset=100.0, frequency=1.0)
    t = np.array([0.0, 0.25, 0.5])
    np.testing.assert_allclose(r.evaluate(t)[0], [100.0, 180.0, 100.0], atol=1e-12)
    assert r.period == 1.0


def test_sharp_triangle():
    r = Triangle(amplitude=90.0, offset=100.0, frequency=1.0)
    t = np.array([0.0, 0.25, 0.5, 0.75])
    xd, v, a = r.evaluate(t)
    # same phase convention as the sine: rises through the offset at t = 0
    np.testing.assert_allclose(xd, [100.0, 190.0, 100.0, 10.0], atol=1e-9)
    np.testing.assert_allclose(v[[0, 2]], [360.0, -360.0])
    np.testing.assert_array_equal(a, 0.0)  # corner impulses are dropped


def test_blended_triangle_is_continuous_and_close():
    sharp = Triangle(amplitude=90.0, offset=100.0, frequency=1.0)
    soft = Triangle(amplitude=90.0, offset=100.0, frequency=1.0, corner_time=0.02)
    t = np.linspace(0, 2, 200001)
    xs, vs, _ = soft.evaluate(t)
    assert np.abs(np.diff(xs)).max() < 360.0 * 1e-5 * 1.01
    assert np.abs(np.diff(vs)).max() < 1.0
    # the blend cuts each corner by v tau / 4
    assert np.abs(xs - sharp.evaluate(t)[0]).max() == pytest.approx(360.0 * 0.02 / 4, rel=1e-3)


def test_step_without_rise():
    r = Step(amplitude=5.0, offset=1.0, t_step=0.5)
    xd, v, a = r.evaluate(np.array([0.0, 0.5, 1.0]))
    np.testing.assert_array_equal(xd, [1.0, 6.0, 6.0])
    assert r.period is None


@pytest.mark.parametrize(
    "table, match",
    [
        ({"kind": "square", "amplitude": 1}, "kind must be one of"),
        ({"kind": "sine", "amplitude": 1}, "missing key"),
        (
            {"kind": "sine", "amplitude": 1, "frequency": 0},
            r"frequency = 0 is outside the supported range \(0, 1e\+06\] Hz",
        ),
        ({"kind": "sine", "amplitude": "a", "frequency": 1}, "amplitude must be a number"),
        ({"kind": "sine", "amplitude": 1, "frequency": 1, "rise": 1}, "unknown key"),
        (
            {"kind": "triangle", "amplitude": 1, "frequency": 1, "corner_time": 0.6},
            "corner_time must be shorter",
        ),
        (
            {"kind": "step", "amplitude": 1, "rise_time": -1},
            r"rise_time = -1 is outside the supported range \[0, 1e\+06\] s",
        ),
    ],
)
def test_bad_reference_tables(table, match):
    with pytest.raises(ConfigError, match=match):
        reference_from_dict(table)
