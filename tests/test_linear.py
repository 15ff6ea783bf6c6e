"""Linear analysis of the error dynamics (python-control) against the LMI tiers."""

import math

import control
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bwdesign import BoucWenParams, GainError, InputError, certify, preset
from bwdesign.certify.checks import sector_interval
from bwdesign.certify.linear import (
    error_dynamics,
    error_system,
    hinf_norm,
    hysteresis_bode,
    lipschitz_envelope,
)

PAPER_GAINS = (8.0, 64.0, -512.0)


def _A(params, gains, k=0.0):
    l1, l2, l3 = gains
    return np.array([[-l1, 1.0, 0.0], [-(params.a1 + l2), -params.a2, -params.a1], [-l3, 0.0, -k]])


def test_error_dynamics_poles_and_damping(experiment):
    ed = error_dynamics(experiment, PAPER_GAINS, udot_max=360.9)
    assert ed.k_interval == pytest.approx(sector_interval(experiment, 360.9))
    assert ed.k_interval[0] == 0.0 and ed.k_interval[1] > 0
    for k, sys, p, wn, z in zip(
        ed.k_interval, ed.systems, ed.poles, ed.natural_frequency, ed.damping, strict=True
    ):
        assert isinstance(sys, control.StateSpace)
        np.testing.assert_allclose(sys.A, _A(experiment, PAPER_GAINS, k))
        np.testing.assert_allclose(np.sort_complex(sys.poles()), p, rtol=1e-9)
        np.testing.assert_allclose(wn, np.abs(p))
        np.testing.assert_allclose(z, -p.real / np.abs(p))
    assert ed.stable
    # the paper's gains leave a lightly damped pair near the stage resonance (352 rad/s)
    assert ed.damping[0].min() < 0.1
    assert 340 < ed.natural_frequency[0][ed.damping[0].argmin()] < 360
    # the dissipative hysteresis error (k > 0) adds damping
    assert ed.damping[1].min() > ed.damping[0].min()
    doc = ed.to_dict()
    assert len(doc["ends"]) == 2 and doc["stable"] is True


def test_bode_peak_is_hinf(experiment):
    b = hysteresis_bode(experiment, PAPER_GAINS)
    assert b.magnitude.max() <= b.peak * (1 + 1e-9)
    assert b.magnitude.max() >= b.peak * (1 - 1e-6)  # the grid includes the peak frequency
    assert b.omega_peak == pytest.approx(351.26, rel=1e-3)
    assert b.lipschitz_envelope == pytest.approx(155.03, rel=1e-3)
    # |G(j w)| from the unscaled state space agrees with the scaled evaluation
    A = _A(experiment, PAPER_GAINS)
    e3 = np.array([0.0, 0.0, 1.0])
    for w, m in zip(b.omega[::50], b.magnitude[::50], strict=True):
        g = e3 @ np.linalg.solve(1j * w * np.eye(3) - A, e3)
        assert abs(g) == pytest.approx(m, rel=1e-8)
    # DC gain: G(0) = (l1 a2 + a1 + l2) / (-a1 l3)
    l1, l2, l3 = PAPER_GAINS
    b0 = hysteresis_bode(experiment, PAPER_GAINS, omega=[1e-6])
    g0 = (l1 * experiment.a2 + experiment.a1 + l2) / (-experiment.a1 * l3)
    assert b0.magnitude[0] == pytest.approx(g0, rel=1e-6)


def test_paper_lipschitz_envelopes_match_lmi(experiment, simulation):
    """The LMI tier's envelope is the H-infinity figure to 1 % (KYP)."""
    cases = [
        (experiment, PAPER_GAINS, 360.9),
        (simulation, (40.0, 40.0, -80.0), 18.2),
        (simulation, (80.0, 160.0, -640.0), 364.2),
    ]
    for params, gains, v in cases:
        env = lipschitz_envelope(params, gains)
        lmi = certify(params, gains, udot_max=v).tier("lipschitz").max_udot
        assert env / 1.01 <= lmi <= env * 1.0001


def test_decay_shift_matches_lmi(simulation):
    gains = (40.0, 40.0, -80.0)
    mu = 20.0
    env = lipschitz_envelope(simulation, gains, decay=mu)
    lmi = certify(simulation, gains, udot_max=18.2, decay=mu).tier("lipschitz").max_udot
    assert env < lipschitz_envelope(simulation, gains)
    assert env / 1.01 <= lmi <= env * 1.0001
    # beyond the spectral abscissa there is no envelope at all
    peak, _ = hinf_norm(simulation, gains, decay=1e4)
    assert peak == math.inf and lipschitz_envelope(simulation, gains, decay=1e4) == 0.0


@st.composite
def stages(draw):
    a1 = 10 ** draw(st.floats(3.0, 9.0))
    w0 = math.sqrt(a1)
    a2 = 2 * draw(st.floats(0.05, 0.9)) * w0
    beta = draw(st.floats(0.05, 2.0))
    gamma = draw(st.floats(-1.0, 1.0)) * beta
    params = BoucWenParams(a1=a1, a2=a2, a3=a1, alpha=1.0, beta=beta, gamma=gamma)
    s1 = w0 * 10 ** draw(st.floats(-1.5, 0.5))
    wo = w0 * 10 ** draw(st.floats(-0.5, 0.5))
    zo = draw(st.floats(0.1, 0.9))
    pair = -zo * wo + 1j * wo * math.sqrt(1 - zo * zo)
    c = np.real(np.poly([-s1, pair, np.conj(pair)]))
    l1 = c[1] - a2
    return params, (l1, c[2] - a1 - l1 * a2, -c[3] / a1), np.array([-s1, pair, np.conj(pair)])


@settings(
    max_examples=12,
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(stages())
def test_random_stages_hinf_and_poles(case):
    params, gains, poles = case
    ed = error_dynamics(params, gains, udot_max=1.0)
    np.testing.assert_allclose(ed.poles[0], np.sort_complex(poles), rtol=1e-7)
    b = hysteresis_bode(params, gains, n=200)
    assert b.magnitude.max() <= b.peak * (1 + 1e-7)
    env = b.lipschitz_envelope
    lmi = certify(params, gains, udot_max=env).tier("lipschitz")
    assert env / 1.01 <= lmi.max_udot <= env * 1.0001


def test_bad_inputs(experiment):
    with pytest.raises(GainError, match="not Hurwitz"):
        error_dynamics(experiment, (8.0, 64.0, 512.0), udot_max=1.0)
    with pytest.raises(InputError, match="udot_max"):
        error_dynamics(experiment, PAPER_GAINS, udot_max=-1.0)
    with pytest.raises(InputError, match="omega"):
        hysteresis_bode(experiment, PAPER_GAINS, omega=[0.0, 1.0])
    with pytest.raises(InputError, match="decay"):
        hinf_norm(experiment, PAPER_GAINS, decay=float("nan"))


def test_error_system_shift(simulation):
    sys = error_system(simulation, (80.0, 160.0, -640.0), k=100.0, decay=10.0)
    A = _A(simulation, (80.0, 160.0, -640.0), 100.0) + 10.0 * np.eye(3)
    np.testing.assert_allclose(sys.A, A)
    assert preset("paper_simulation_corrected") == simulation
