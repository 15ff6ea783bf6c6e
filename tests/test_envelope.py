import numpy as np
import pytest

from bwdesign import InputError, Sine, Step, Triangle, derive_envelope, simulate_zoh
from bwdesign.model.envelope import feedforward_input


def test_paper_sine_envelope(experiment):
    env = derive_envelope(experiment, Sine(amplitude=80.0, offset=100.0, frequency=1.0))
    # leading order (a1/a3) * 80 * 2 pi
    assert env.leading_order == pytest.approx(experiment.a1 / experiment.a3 * 160 * np.pi)
    assert env.derived == pytest.approx(360.9, abs=0.5)
    assert env.udot_max == env.derived


def test_feedforward_inverse_tracks_exactly(experiment):
    """The exact-inverse input, held at a fine rate, makes x1 follow x_d."""
    ref = Sine(amplitude=80.0, offset=100.0, frequency=1.0)
    dt = 2e-5
    t = np.arange(0.0, 2.0, dt)
    u, udot, h = feedforward_input(experiment, ref, t)
    X = simulate_zoh(
        experiment, u, dt, np.array([ref.evaluate(0.0)[0], ref.evaluate(0.0)[1], h[0]]), u_prev=u[0]
    )
    err = X[1:, 0] - ref.evaluate(t + dt)[0]
    assert np.abs(err[t > 1.0]).max() < 0.05  # um, of 160 um travel; the ZOH lag is dt/2
    np.testing.assert_allclose(np.gradient(u, dt)[5:-5], udot[5:-5], rtol=2e-3, atol=0.5)


def test_triangle_envelope_exceeds_leading_order(experiment):
    """On a triangle the rate peaks just after a corner, where dh/du is largest."""
    env = derive_envelope(experiment, Triangle(amplitude=90.0, offset=100.0, frequency=1.0))
    assert env.derived > 1.1 * env.leading_order


def test_margin_and_bad_inputs(experiment):
    ref = Sine(amplitude=10.0, offset=0.0, frequency=2.0)
    env = derive_envelope(experiment, ref, margin=1.5)
    assert env.udot_max == pytest.approx(1.5 * env.derived)
    with pytest.raises(InputError, match="margin"):
        derive_envelope(experiment, ref, margin=0.5)
    with pytest.raises(InputError, match="sharp step"):
        derive_envelope(experiment, Step(amplitude=1.0))
