import numpy as np
import pytest

from bwdesign import InputError, steady_state_window, tracking_metrics


def test_metrics_values():
    t = np.arange(6.0)
    e = np.array([10.0, -10.0, 1.0, -2.0, 2.0, -1.0])
    m = tracking_metrics(e, t, window=(2.0, 5.0))
    assert m.maxe == 2.0
    assert m.me == pytest.approx(1.5)
    assert m.rmse == pytest.approx(np.sqrt(2.5))
    assert m.samples == 4 and m.window == (2.0, 5.0)


def test_window_default_is_two_periods():
    t = np.linspace(0, 5, 501)
    assert steady_state_window(t, 1.0) == (3.0, 5.0)
    assert steady_state_window(t, None) == (2.5, 5.0)
    assert steady_state_window(t, 10.0) == (2.5, 5.0)


@pytest.mark.parametrize(
    "e, t, window, match",
    [
        (np.zeros((2, 2)), None, None, "1-D"),
        (np.zeros(3), np.zeros(2), None, "same shape"),
        (np.zeros(3), np.arange(3.0), (5.0, 6.0), "holds no sample"),
        (np.array([0.0, np.nan]), np.arange(2.0), None, "not finite"),
    ],
)
def test_bad_metric_inputs(e, t, window, match):
    with pytest.raises(InputError, match=match):
        tracking_metrics(e, t, window)
