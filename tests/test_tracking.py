"""The tracking law (paper eq. 12) and its sampled form."""

import math
import warnings

import numpy as np
import pytest

from bwdesign import DiscreteTrackingController, TrackingController, TuningWarning
from bwdesign.control.controllers import (
    discrete_error_gains,
    discrete_integral_gains,
    eq12,
    error_feedback_gains,
    make_controller,
    solve_jump,
)
from bwdesign.errors import GainError, InputError
from bwdesign.model.plant import discretize, hysteresis_increment

DT = 2e-4


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_eq12_term_by_term(usable_plant, seed):
    """Every term of eq. (12), written out from the paper, and their sum."""
    p = usable_plant
    rng = np.random.default_rng(seed)
    l1, l2 = 10 ** rng.uniform(0, 3), 10 ** rng.uniform(0.3, 3)
    xhat = rng.normal(size=3) * (30.0, 3000.0, 1.0)
    ref = tuple(rng.normal(size=3) * (30.0, 300.0, 3e4))
    xd, vd, ad = ref
    c = TrackingController(p, l1, l2)
    t = c.terms(xhat, ref)
    e_hat = xhat[0] - xd  # e^ = x1^ - x_d
    e_delta = xhat[1] - vd  # e^_delta = x2^ - x_d'
    assert t.feedforward == pytest.approx(ad / p.a3, rel=1e-13)
    assert t.stiffness == pytest.approx(p.a1 * xhat[0] / p.a3, rel=1e-13)
    assert t.hysteresis == pytest.approx(p.a1 * xhat[2] / p.a3, rel=1e-13)
    assert t.damping == pytest.approx(p.a2 * xhat[1] / p.a3, rel=1e-13)
    assert t.velocity_error == pytest.approx(-l1 * e_delta / p.a3, rel=1e-13)
    assert t.sliding == pytest.approx(-l2 * (l1 * e_hat + e_delta) / p.a3, rel=1e-13)
    paper = (
        ad
        + p.a1 * (xhat[0] + xhat[2])
        + p.a2 * xhat[1]
        - l1 * e_delta
        - l2 * (l1 * e_hat + e_delta)
    ) / p.a3
    parts = (t.feedforward, t.stiffness, t.hysteresis, t.damping, t.velocity_error, t.sliding)
    scale = sum(abs(v) for v in parts)
    assert sum(parts) == pytest.approx(paper, abs=1e-13 * scale)
    assert t.unsaturated == pytest.approx(paper, abs=1e-13 * scale)
    assert c(xhat, ref) == pytest.approx(paper, abs=1e-13 * scale)
    assert eq12(p, l1, l2, xhat, xd, vd, ad) == pytest.approx(paper, abs=1e-13 * scale)
    # the linear form used by the loop analysis and the fast simulation path
    Kx, Kr = c.linear_gains()
    assert Kx @ xhat + Kr @ np.array(ref) == pytest.approx(paper, abs=1e-12 * scale)
    assert np.allclose(c.gains, error_feedback_gains(p, l1, l2))


def test_eq12_vectorised(experiment):
    rng = np.random.default_rng(3)
    X = rng.normal(size=(5, 3))
    r = rng.normal(size=(3, 5))
    u = eq12(experiment, 2.0, 3.0, X, *r)
    c = TrackingController(experiment, 2.0, 3.0)
    for k in range(5):
        assert u[k] == pytest.approx(c(X[k], tuple(r[:, k])), rel=1e-12)


def test_perfect_estimate_cancels_plant(experiment):
    """With xhat = x the closed loop is e'' + (l1 + l2) e' + l1 l2 e = 0 (paper eq. 16)."""
    p = experiment
    l1, l2 = 7.0, 11.0
    x = np.array([12.0, -300.0, 0.4])
    ref = (10.0, -250.0, 900.0)
    u = TrackingController(p, l1, l2)(x, ref)
    x2dot = -p.a1 * x[0] - p.a2 * x[1] - p.a1 * x[2] + p.a3 * u
    e, ed = x[0] - ref[0], x[1] - ref[1]
    edd = x2dot - ref[2]
    assert edd + (l1 + l2) * ed + l1 * l2 * e == pytest.approx(0.0, abs=1e-9 * abs(p.a1 * x[0]))


def test_saturation_and_estimate_limits(experiment):
    c = TrackingController(experiment, 1.0, 2.0, u_limits=(-30.0, 130.0))
    assert c([1e4, 0, 0], (0.0, 0.0, 0.0)) == 130.0
    assert c([-1e4, 0, 0], (0.0, 0.0, 0.0)) == -30.0
    t = c.terms([1e4, 0, 0], (0.0, 0.0, 0.0))
    assert t.unsaturated > 130.0 and t.u == 130.0
    c2 = TrackingController(experiment, 1.0, 2.0, estimate_limits=((0.0, 200.0), None, (-1.0, 1.0)))
    plain = TrackingController(experiment, 1.0, 2.0)
    assert c2([500.0, 3.0, 5.0], (0, 0, 0)) == pytest.approx(plain([200.0, 3.0, 1.0], (0, 0, 0)))


BAD_LAMBDAS = [
    (
        "lambda1 zero",
        dict(lambda1=0.0, lambda2=2.0),
        GainError,
        r"lambda1 \(1/s\) = 0 is outside the supported range \(0, 1e\+12\] 1/s",
    ),
    ("lambda1 negative", dict(lambda1=-1.0, lambda2=2.0), GainError, "lambda1"),
    ("lambda2 negative", dict(lambda1=1.0, lambda2=-2.0), GainError, "lambda2"),
    ("lambda2 nan", dict(lambda1=1.0, lambda2=math.nan), GainError, "lambda2"),
    ("lambda1 string", dict(lambda1="1", lambda2=2.0), GainError, "must be a number"),
    ("lambda1 bool", dict(lambda1=True, lambda2=2.0), GainError, "must be a number"),
]


@pytest.mark.parametrize("label, kw, err, match", BAD_LAMBDAS, ids=[b[0] for b in BAD_LAMBDAS])
def test_bad_lambdas(experiment, label, kw, err, match):
    with pytest.raises(err, match=match):
        TrackingController(experiment, **kw)
    assert issubclass(err, ValueError)


def test_lambda2_below_three_halves_warns_only(experiment):
    with pytest.warns(TuningWarning, match=r"lambda2 = 1 <= 3/2"):
        c = TrackingController(experiment, 1.0, 1.0)
    assert c.lambda2 == 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        TrackingController(experiment, 1.0, 1.6)  # no warning above 3/2


BAD_LIMITS = [
    ("reversed u_limits", dict(u_limits=(10.0, -10.0)), "u_min < u_max"),
    ("u_limits scalar", dict(u_limits=5.0), "pair"),
    ("u_limits nan", dict(u_limits=(math.nan, 1.0)), "u_min < u_max"),
    ("estimate_limits short", dict(estimate_limits=((0, 1), (0, 1))), "three"),
    ("estimate_limits reversed", dict(estimate_limits=((1, 0), None, None)), "lo < hi"),
]


@pytest.mark.parametrize("label, kw, match", BAD_LIMITS, ids=[b[0] for b in BAD_LIMITS])
def test_bad_limits(experiment, label, kw, match):
    with pytest.raises(InputError, match=match):
        TrackingController(experiment, 1.0, 2.0, **kw)


def test_params_type_checked():
    with pytest.raises(InputError, match="BoucWenParams"):
        TrackingController({"a1": 1.0}, 1.0, 2.0)


@pytest.mark.parametrize("lams", [(1.0, 2.0), (50.0, 300.0), (240.0, 240.0)])
def test_discrete_gains_place_sampled_poles(usable_plant, lams):
    p = usable_plant
    k = discrete_error_gains(p, *lams, DT)
    z = discretize(p, DT)
    # characteristic polynomials (robust for the repeated pole of lambda1 = lambda2)
    got = np.poly(z.F[:2, :2] + np.outer(z.g[:2], k))
    want = np.poly(np.exp(-np.array(lams) * DT))
    assert np.allclose(got, want, rtol=0, atol=1e-10)


def test_discrete_gains_tend_to_eq12(experiment):
    cont = error_feedback_gains(experiment, 30.0, 50.0)
    disc = discrete_error_gains(experiment, 30.0, 50.0, 1e-7)
    assert np.allclose(disc, cont, rtol=1e-4)


def test_integral_gains_place_three_poles(experiment):
    k = discrete_integral_gains(experiment, 200.0, 300.0, 100.0, DT)
    z = discretize(experiment, DT)
    Phi = np.zeros((3, 3))
    Phi[:2, :2] = z.F[:2, :2]
    Phi[2, 0], Phi[2, 2] = DT, 1.0
    Gam = np.array([z.g[0], z.g[1], 0.0])
    ev = np.sort(np.linalg.eigvals(Phi + np.outer(Gam, k)).real)
    assert np.allclose(ev, np.sort(np.exp(-np.array([200.0, 300.0, 100.0]) * DT)), atol=1e-9)


def test_discrete_controller_integrates_and_resets(experiment):
    c = DiscreteTrackingController(experiment, 200.0, 200.0, dt=DT, integral_rate=100.0)
    x, ref = [1.0, 0.0, 0.0], (0.0, 0.0, 0.0)
    u0 = c(x, ref)
    assert c.q == pytest.approx(DT * 1.0)
    u1 = c(x, ref)
    assert u1 == pytest.approx(u0 + c.ki * DT)
    c.reset()
    assert c.q == 0.0 and c(x, ref) == pytest.approx(u0)
    with pytest.raises(NotImplementedError):
        c.terms(x, ref)


def test_make_controller_forms(experiment):
    assert make_controller(experiment, 1.0, 2.0).form == "continuous"
    assert make_controller(experiment, 1.0, 2.0, form="discrete", dt=DT).form == "discrete"
    with pytest.raises(InputError, match="needs the sample time"):
        make_controller(experiment, 1.0, 2.0, form="discrete")
    with pytest.raises(InputError, match="discrete form only"):
        make_controller(experiment, 1.0, 2.0, integral_rate=3.0)
    with pytest.raises(InputError, match="'continuous' or 'discrete'"):
        make_controller(experiment, 1.0, 2.0, form="hybrid")


def test_solve_jump_satisfies_implicit_law(experiment):
    p = experiment
    c = p.a1 / p.a3
    for h, up, u0 in [(0.2, 50.0, 60.0), (-0.9, 80.0, 20.0), (1.0, 10.0, 10.0)]:
        u = solve_jump(p, u0, c, h, up)
        assert u == pytest.approx(u0 + c * hysteresis_increment(p, h, up, u), abs=1e-10)
    # with x3hat far outside the hysteresis range a small decreasing jump has
    # c dh/du = c (alpha + (beta - gamma) 6) > 1: ill-posed, the pre-jump law is returned
    naive = 30.0 + c * 6.0
    assert c * (p.alpha + (p.beta - p.gamma) * 6.0) > 1
    assert solve_jump(p, 30.0, c, 6.0, naive + 0.01) == naive


def test_hysteresis_jump_needs_u_prev(experiment):
    c = TrackingController(experiment, 1.0, 2.0, hysteresis_jump=True)
    with pytest.raises(InputError, match="u_prev"):
        c([0.0, 0.0, 0.0], (0.0, 0.0, 0.0))
    assert math.isfinite(c([0.0, 0.0, 0.0], (0.0, 0.0, 0.0), u_prev=1.0))
