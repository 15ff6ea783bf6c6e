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


def test_the_envelope_is_kept_by_its_exact_arguments(experiment, monkeypatch):
    """Asked again with the same arguments, the envelope comes back without the inverse
    being run; the next float of the amplitude, another margin or another stage is a new
    envelope; a reference that does not pickle is derived every time."""
    from bwdesign.memo import Memo
    from bwdesign.model import envelope as E

    runs = []
    real = E.feedforward_input

    def counted(*a, **k):
        runs.append(1)
        return real(*a, **k)

    monkeypatch.setattr(E, "_ENVELOPES", Memo(16))
    monkeypatch.setattr(E, "feedforward_input", counted)
    ref = Sine(amplitude=80.0, offset=100.0, frequency=1.0)
    a = derive_envelope(experiment, ref)
    assert derive_envelope(experiment, ref) == a and len(runs) == 1
    assert derive_envelope(experiment, Sine(amplitude=80.0, offset=100.0, frequency=1.0)) == a
    assert len(runs) == 1
    b = derive_envelope(experiment, Sine(amplitude=np.nextafter(80.0, 81.0), offset=100.0,
                                         frequency=1.0))  # fmt: skip
    c = derive_envelope(experiment, ref, margin=1.5)
    assert len(runs) == 3 and b.udot_max != a.udot_max and c.udot_max == 1.5 * a.udot_max

    class Local(Sine):  # defined in a function: does not pickle
        pass

    local = Local(amplitude=80.0, offset=100.0, frequency=1.0)
    assert derive_envelope(experiment, local).udot_max == a.udot_max
    assert derive_envelope(experiment, local).udot_max == a.udot_max
    assert len(runs) == 5
    with pytest.raises(InputError, match="sharp step"):  # refusals are never kept
        derive_envelope(experiment, Step(amplitude=1.0))
    assert len(E._ENVELOPES) == 3
