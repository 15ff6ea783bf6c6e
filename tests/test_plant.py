"""Exactness of the sampled-data plant against an independent integration."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from bwdesign import UnboundedModelError, hysteresis_increment, preset, simulate_zoh, zoh_step
from bwdesign.errors import InputError
from bwdesign.model.params import BoucWenParams
from bwdesign.model.plant import discretize, rhs

DT = 2e-4


def reference_step(p, x, u_prev, u, dt):
    """Independent reference: hysteresis integrated in u along the jump, then
    the linear part integrated in time with x3 and u frozen (solve_ivp, DOP853)."""
    x1, x2, h = x
    if u != u_prev:
        s = math.copysign(1.0, u - u_prev)
        sol = solve_ivp(
            lambda _v, y: [p.alpha - p.beta * s * y[0] - p.gamma * abs(y[0])],
            (u_prev, u),
            [h],
            method="DOP853",
            rtol=1e-12,
            atol=1e-14,
        )
        h = sol.y[0, -1]
    sol = solve_ivp(
        lambda _t, y: [y[1], -p.a1 * y[0] - p.a2 * y[1] - p.a1 * h + p.a3 * u],
        (0.0, dt),
        [x1, x2],
        method="DOP853",
        rtol=1e-12,
        atol=1e-12,
    )
    return np.array([sol.y[0, -1], sol.y[1, -1], h])


@pytest.mark.parametrize("seed", [0, 1])
def test_exact_against_independent_integration(usable_plant, seed):
    p = usable_plant
    rng = np.random.default_rng(seed)
    span = 6.0 if p.a1 > 1e6 else 120.0
    # a random walk with frequent reversals, plus a few large jumps
    u = np.cumsum(rng.normal(0.0, 0.05 * span, 150))
    u[rng.integers(0, 150, 5)] += rng.normal(0, span, 5)
    x0 = np.array([1.0, 0.0, 0.3])
    X = simulate_zoh(p, u, DT, x0, u_prev=0.0)
    ref = np.empty_like(X)
    ref[0] = x0
    up = 0.0
    for k, uk in enumerate(u):
        ref[k + 1] = reference_step(p, ref[k], up, uk, DT)
        up = uk
    scale = np.abs(ref).max(axis=0)
    rel = np.abs(X - ref).max(axis=0) / scale
    assert rel.max() < 1e-8, rel


def test_row_convention(experiment):
    u = np.array([10.0, 20.0, 20.0])
    X = simulate_zoh(experiment, u, DT, np.zeros(3), u_prev=5.0)
    assert X.shape == (4, 3)
    np.testing.assert_array_equal(X[0], np.zeros(3))
    np.testing.assert_allclose(X[1], zoh_step(experiment, np.zeros(3), 5.0, 10.0, DT), rtol=1e-15)
    np.testing.assert_allclose(X[2], zoh_step(experiment, X[1], 10.0, 20.0, DT), rtol=1e-14)
    # no jump at the last sample: x3 unchanged
    assert X[3, 2] == X[2, 2]


def test_static_equilibrium(experiment):
    """Holding u for long reaches x1 = (a3/a1) u - x3."""
    X = simulate_zoh(experiment, np.full(2000, 50.0), 1e-3, np.zeros(3))
    assert X[-1, 0] == pytest.approx(experiment.static_gain * 50.0 - X[-1, 2], rel=1e-9)


def test_exact_is_stable_where_forward_euler_diverges(simulation):
    """Section 4 plant at 0.2 ms: its 2 kHz resonance makes forward Euler unstable."""
    p = simulation
    t = np.arange(0.0, 0.5, DT)
    u = 3.0 * np.sin(0.4 * np.pi * t - 0.5 * np.pi) + 3.0
    X = simulate_zoh(p, u, DT, np.array([10.0, 2.0, 2.0]))
    assert np.all(np.isfinite(X))
    assert np.abs(X[:, 0]).max() < 100.0  # um; the static range is about 0..60

    x = np.array([10.0, 2.0, 2.0])
    up = u[0]
    peak = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        for uk in u[:2000]:
            x = x + DT * rhs(p, x, uk, (uk - up) / DT)
            up = uk
            peak = max(peak, abs(x[0]))
    assert not (peak < 1e6), "forward Euler should diverge on this plant at 0.2 ms"
    eig = np.linalg.eigvals(np.array([[0.0, 1.0], [-p.a1, -p.a2]]))
    assert np.abs(1 + eig * DT).max() > 2.5  # |1 + lambda dt| ~ 2.6


def test_discrete_poles_are_exp_of_continuous(usable_plant):
    z = discretize(usable_plant, DT)
    eig_c = np.linalg.eigvals(np.array([[0.0, 1.0], [-usable_plant.a1, -usable_plant.a2]]))
    eig_d = np.linalg.eigvals(z.F[:2, :2])
    np.testing.assert_allclose(
        np.sort_complex(eig_d), np.sort_complex(np.exp(eig_c * DT)), rtol=1e-10
    )


def test_unbounded_model_is_refused_unless_allowed():
    p = preset("paper_simulation")
    t = np.arange(0.0, 5.0, DT)
    u = 3.0 * np.sin(0.4 * np.pi * t - 0.5 * np.pi) + 3.0
    with pytest.raises(UnboundedModelError):
        simulate_zoh(p, u, DT, np.zeros(3))
    X = simulate_zoh(p, u, DT, np.array([10.0, 2.0, 2.0]), allow_unbounded=True)
    # as printed, x3 grows without bound on the rising input
    # (docs/design.md, section "The simulation parameter set")
    assert not np.all(np.abs(X[:, 2]) < 1e6)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(u=np.zeros((2, 2))), "1-D"),
        (dict(u=np.array([0.0, np.nan])), "finite"),
        (dict(dt=0.0), r"dt \(s\) = 0 is outside"),
        (dict(dt=-1e-3), r"dt \(s\) = -0.001 is outside"),
        (dict(x0=np.zeros(2)), r"shape \(3,\)"),
        (dict(x0=np.array([0.0, np.inf, 0.0])), "finite"),
        (dict(u_prev=math.nan), "u_prev"),
    ],
    ids=["u-2d", "u-nan", "dt-zero", "dt-neg", "x0-shape", "x0-inf", "uprev-nan"],
)
def test_bad_inputs(experiment, kwargs, match):
    args = dict(u=np.zeros(3), dt=DT, x0=np.zeros(3), u_prev=0.0)
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        simulate_zoh(experiment, args["u"], args["dt"], args["x0"], u_prev=args["u_prev"])


# -- hysteresis_increment properties ------------------------------------------

bounded_params = st.builds(
    lambda alpha, beta, frac: BoucWenParams(
        a1=1e5, a2=100.0, a3=1e5, alpha=alpha, beta=beta, gamma=frac * beta
    ),
    alpha=st.floats(0.05, 10.0),
    beta=st.floats(0.01, 3.0),
    frac=st.floats(-0.95, 1.0),  # |gamma| <= beta, beta + gamma > 0
)
volts = st.floats(-200.0, 200.0, allow_nan=False)


def _hmax(p):
    return p.alpha / (p.beta + p.gamma)


@settings(max_examples=300, deadline=None)
@given(p=bounded_params, h0=st.floats(-5.0, 5.0), u=st.lists(volts, min_size=3, max_size=3))
def test_composition_over_monotone_path(p, h0, u):
    u0, u1, u2 = sorted(u)
    for a, b, c in ((u0, u1, u2), (u2, u1, u0)):
        two = hysteresis_increment(p, hysteresis_increment(p, h0, a, b), b, c)
        one = hysteresis_increment(p, h0, a, c)
        assert two == pytest.approx(one, rel=1e-9, abs=1e-11)


@settings(max_examples=300, deadline=None)
@given(p=bounded_params, h0=st.floats(-20.0, 20.0), u0=volts, u1=volts)
def test_bounded_class_stays_bounded(p, h0, u0, u1):
    h1 = hysteresis_increment(p, h0, u0, u1)
    assert abs(h1) <= max(abs(h0), _hmax(p)) * (1 + 1e-12) + 1e-12


@settings(max_examples=300, deadline=None)
@given(p=bounded_params, frac=st.floats(-1.0, 1.0), u0=volts, u1=volts)
def test_increment_has_the_sign_of_the_input_step(p, frac, u0, u1):
    h0 = frac * _hmax(p)
    h1 = hysteresis_increment(p, h0, u0, u1)
    assert (h1 - h0) * (u1 - u0) >= -1e-12 * (1 + abs(u1 - u0))


@settings(max_examples=300, deadline=None)
@given(p=bounded_params, frac=st.floats(0.01, 0.99), u0=volts, du=st.floats(0.5, 100.0))
def test_reversal_does_not_retrace(p, frac, u0, du):
    """A reversal takes another path: with x3 > 0 the descent is steeper than the
    ascent (dh/du differs by 2 beta x3), so up-then-back ends strictly below the
    start; mirrored, down-then-back from x3 < 0 ends strictly above."""
    h0 = frac * _hmax(p)
    up = hysteresis_increment(p, h0, u0, u0 + du)
    back = hysteresis_increment(p, up, u0 + du, u0)
    assert back < h0 - 1e-9 * _hmax(p)
    down = hysteresis_increment(p, -h0, u0, u0 - du)
    again = hysteresis_increment(p, down, u0 - du, u0)
    assert again > -h0 + 1e-9 * _hmax(p)


def _increment_always_log1p(p, h, u0, u1):
    """hysteresis_increment as it was before the zero crossing was decided without log1p:
    the crossing computed for every jump against its direction."""

    def branch(h, w, c):  # dh/dw = alpha - c h over w, as bwdesign.model.plant solves it
        x = c * w
        try:
            e = math.expm1(-x)
        except OverflowError:
            return math.copysign(math.inf, h if h != 0 else p.alpha)
        if abs(x) < 1e-8:
            return h + (h * e + p.alpha * w * (1.0 - x / 2.0 + x * x / 6.0))
        return h + e * (h - p.alpha / c)

    du = u1 - u0
    if du == 0.0:
        return float(h)
    s = 1.0 if du > 0.0 else -1.0
    g, w = s * h, abs(du)
    if g < 0.0:
        cm = p.beta - p.gamma
        if cm == 0.0:
            wz = -g / p.alpha
        else:
            arg = -cm * g / p.alpha
            wz = math.log1p(arg) / cm if arg > -1.0 else math.inf
        if w <= wz:
            return s * branch(g, w, cm)
        g, w = 0.0, w - wz
    return s * branch(g, w, p.beta + p.gamma)


def test_the_crossing_decided_without_log1p_changes_no_bit():
    """Jumps against their direction over every scale (short and long against the
    crossing, states near zero, beta - gamma of either sign and zero, unbounded models):
    the state after the jump is the one computing the crossing every time gives, bit for
    bit, the compiled jump of the batched loop too."""
    from bwdesign.sim.compiled import hysteresis_jump

    rng = np.random.default_rng(11)
    cases = 0
    for _ in range(60):
        alpha = float(10 ** rng.uniform(-2, 1))
        beta = float(rng.choice([-1.0, 1.0], p=[0.2, 0.8]) * 10 ** rng.uniform(-3, 0))
        gamma = float(rng.choice([beta, beta * rng.uniform(0, 2), 10 ** rng.uniform(-3, 0)]))
        p = BoucWenParams(a1=1.0, a2=1.0, a3=1.0, alpha=alpha, beta=beta, gamma=gamma)
        h = rng.choice([-1.0, 1.0], 400) * 10 ** rng.uniform(-9, 1, 400)
        u0 = rng.uniform(-100, 100, 400)
        du = rng.choice([-1.0, 1.0], 400) * 10 ** rng.uniform(-10, 2.5, 400)
        for hk, a, d in zip(h.tolist(), u0.tolist(), du.tolist(), strict=True):
            want = _increment_always_log1p(p, hk, a, a + d)
            got = hysteresis_increment(p, hk, a, a + d)
            jit = hysteresis_jump(alpha, beta, gamma, hk, a, a + d)
            assert got == want or (math.isnan(got) and math.isnan(want)), (p, hk, a, d)
            assert jit == want or (math.isnan(jit) and math.isnan(want)), (p, hk, a, d)
            cases += 1
    assert cases == 24_000


def test_the_branch_from_one_expm1_is_as_exact_as_with_exp():
    """Each branch of the jump, ``h e^-x + alpha w (1 - e^-x)/x`` (x = c w), computed as
    ``h + e (h - alpha / c)`` from ``e = expm1(-x)`` alone: against the value to 40
    digits (mpmath), over states, lengths and slopes of every scale, its error stays
    within 2 roundings of the terms' size (measured: 1.04), as the form with exp did (1.02)."""
    import mpmath

    from bwdesign.sim.compiled import hysteresis_jump

    mpmath.mp.dps = 40
    rng = np.random.default_rng(5)
    eps = np.finfo(float).eps
    worst_new = worst_old = 0.0
    for _ in range(3000):
        alpha = float(10 ** rng.uniform(-2, 1))
        c = float(10 ** rng.uniform(-4, 1))
        # a state on the g >= 0 branch (beta + gamma = c) anywhere in [0, alpha / c]
        g = float(rng.uniform(0, 1) * alpha / c)
        w = float(10 ** rng.uniform(-10, 2.5))
        x = mpmath.mpf(c) * mpmath.mpf(w)
        p = BoucWenParams(a1=1.0, a2=1.0, a3=1.0, alpha=alpha, beta=c / 2, gamma=c / 2)
        exact = mpmath.mpf(g) * mpmath.exp(-x) - mpmath.mpf(alpha) * mpmath.expm1(-x) / c
        got = hysteresis_increment(p, g, 0.0, w)
        assert hysteresis_jump(alpha, c / 2, c / 2, g, 0.0, w) == got
        xf = c * w
        old = g * math.exp(-xf) + alpha * w * (-math.expm1(-xf) / xf)
        size = g + alpha * w * float(-mpmath.expm1(-x) / x)
        worst_new = max(worst_new, float(abs(got - exact)) / (eps * size))
        worst_old = max(worst_old, float(abs(old - exact)) / (eps * size))
    assert worst_new <= 2.0, (worst_new, worst_old)
    assert worst_old <= 2.0, (worst_new, worst_old)


def test_zero_crossing_inside_the_jump(experiment):
    """From a negative state, a rising jump crosses zero and continues on the other branch."""
    p = experiment
    h0 = -0.5
    # distance to the crossing on the beta - gamma branch
    c = p.beta - p.gamma
    wz = math.log1p(-c * h0 / p.alpha) / c
    assert hysteresis_increment(p, h0, 0.0, wz) == pytest.approx(0.0, abs=1e-12)
    h = hysteresis_increment(p, h0, 0.0, wz + 1.0)
    expected = p.alpha / (p.beta + p.gamma) * (1 - math.exp(-(p.beta + p.gamma)))
    assert h == pytest.approx(expected, rel=1e-12)


def test_no_jump_returns_state(experiment):
    assert hysteresis_increment(experiment, 0.37, 12.0, 12.0) == 0.37


def test_hysteresis_slope_range_bounds_every_jump_and_is_attained():
    """|H(h, u0, u1) - h| <= hi |u1 - u0| for |h| <= h_max over random bounded plants, and
    the bound is reached (a small jump away from h = -h_max has slope hi)."""
    from bwdesign.model.plant import hysteresis_slope_range

    rng = np.random.default_rng(3)
    for _ in range(40):
        beta = rng.uniform(0.01, 2.0)
        gamma = rng.uniform(-beta, beta)  # the bounded class: beta - gamma >= 0, beta + gamma > 0
        p = BoucWenParams(a1=1e5, a2=500.0, a3=1e5, alpha=rng.uniform(0.05, 5.0), beta=beta,
                          gamma=gamma)  # fmt: skip
        lo, hi = hysteresis_slope_range(p)
        hm = p.bounded_class().h_max
        assert lo == 0.0 and hi == pytest.approx(2 * p.alpha * beta / (beta + gamma))
        for _ in range(50):
            h = rng.uniform(-hm, hm)
            u0 = rng.uniform(-50, 50)
            u1 = u0 + rng.choice([-1, 1]) * 10 ** rng.uniform(-6, 1)
            j = hysteresis_increment(p, h, u0, u1) - h
            assert abs(j) <= hi * abs(u1 - u0) * (1 + 1e-12) + 1e-15
            assert j * (u1 - u0) >= 0  # the slope is never negative
        w = 1e-7
        assert (hysteresis_increment(p, -hm, 0.0, w) + hm) / w == pytest.approx(hi, rel=1e-5)
    # outside the bounded class: alpha
    q = BoucWenParams(a1=1e5, a2=500.0, a3=1e5, alpha=0.5, beta=0.1, gamma=0.3)
    assert hysteresis_slope_range(q) == (0.5, 0.5)


def _random_box(rng, rel):
    """A random bounded plant's hysteresis (alpha, beta, gamma), the bounded corners of a
    box of +-``rel`` around it, an input step bound and a second-difference bound."""
    from itertools import product

    beta = rng.uniform(0.05, 2.0)
    nominal = dict(alpha=rng.uniform(0.1, 5.0), beta=beta, gamma=rng.uniform(-0.8, 0.8) * beta)
    corners = [
        BoucWenParams(a1=1e5, a2=500.0, a3=1e5,
                      **{k: v * f for (k, v), f in zip(nominal.items(), fs, strict=True)})
        for fs in product((1 - rel, 1 + rel), repeat=3)
    ]  # fmt: skip
    step = 10 ** rng.uniform(-3, 0)
    second = step * 10 ** rng.uniform(-3, -0.5)
    return nominal, [c for c in corners if c.bounded_class().bounded], step, second


def _turning_inputs(rng, step, second, n):
    """Input steps ``v_k`` with ``|v_k| <= step`` and ``|v_k - v_(k-1)| <= second``: runs of
    random length at full, zero or random second difference (reversals of every speed)."""
    v, out = rng.uniform(-step, step), []
    while len(out) < n:
        a = second * rng.choice([-1.0, 1.0, 0.0, rng.uniform(-1, 1)])
        for _ in range(int(rng.integers(1, 4 * max(1, int(step / second))))):
            v = float(np.clip(v + a, -step, step))
            out.append(v)
    return out[:n]


def test_hysteresis_jump_bound_holds_once_the_input_turns_and_is_reached():
    """Over random +-10 % boxes of bounded plants: every jump of a plant inside the box,
    once the input has turned, is within the bound of the box's corners; and for one plant
    the bound is reached (saturated at -h_max, then turning at the largest second difference)."""
    from itertools import product

    from bwdesign.model.plant import hysteresis_jump_bound, hysteresis_slope_range

    rng = np.random.default_rng(5)
    for _ in range(12):
        nominal, corners, step, second = _random_box(rng, 0.1)
        beta, gamma = nominal["beta"], nominal["gamma"]
        hi = max(hysteresis_slope_range(c)[1] for c in corners)
        bound = hysteresis_jump_bound(corners, step, second)
        assert bound <= hi * step and hysteresis_jump_bound(corners, step) == hi * step
        for _ in range(4):
            f = rng.uniform(0.9, 1.1, size=3)
            p = BoucWenParams(a1=1e5, a2=500.0, a3=1e5, alpha=nominal["alpha"] * f[0],
                              beta=beta * f[1], gamma=gamma * f[2])  # fmt: skip
            if not p.bounded_class().bounded:
                continue
            hm = p.bounded_class().h_max
            h, u, turned, worst = rng.uniform(-hm, hm), 0.0, False, 0.0
            prev = None
            for v in _turning_inputs(rng, step, second, 3000):
                turned = turned or (prev is not None and prev * v <= 0)
                h1 = hysteresis_increment(p, h, u, u + v)
                if turned:
                    worst = max(worst, abs(h1 - h))
                h, u, prev = h1, u + v, v
            assert worst <= bound * (1 + 1e-9)
    # the worst input (saturated low, then turning up as fast as allowed) on every corner
    # of wide boxes stays within the box's bound, and for one plant reaches it
    p = preset("paper_experiment")
    step, second = 0.08, 2.5e-4
    for fa, fb, fg in ((0.5, 1.0, 1.0), (1.0, 0.5, 1.0), (1.0, 1.0, 0.2), (0.6, 0.8, 0.5)):
        corners = [
            p.replace(alpha=p.alpha * a, beta=p.beta * b, gamma=p.gamma * g)
            for a, b, g in product((fa, 2 - fa), (fb, 2 - fb), (fg, 2 - fg))
        ]
        bound = hysteresis_jump_bound(corners, step, second)
        assert max(_worst_turn(c, step, second) for c in corners) <= bound * (1 + 1e-9)
    bound = hysteresis_jump_bound([p], step, second)
    assert 0.98 * bound <= _worst_turn(p, step, second) <= bound
    assert bound < 0.25 * hysteresis_slope_range(p)[1] * step  # what the turn buys here


def _worst_turn(p, step, second):
    """The largest jump of ``p`` from ``x3 = -h_max`` as the input turns up with second
    differences ``second`` until its steps reach ``step``."""
    h, u, v, reached = -p.bounded_class().h_max, 0.0, 0.0, 0.0
    for _ in range(int(step / second) + 50):
        v = min(step, v + second)
        h1 = hysteresis_increment(p, h, u, u + v)
        reached, h, u = max(reached, h1 - h), h1, u + v
    return reached


def test_hysteresis_jump_bound_refuses_bad_input():
    from bwdesign.model.plant import hysteresis_jump_bound

    p = preset("paper_experiment")
    for args, match in (
        (([], 0.1, 1e-3), "at least one plant"),
        (([p], -0.1, 1e-3), "step"),
        (([p], 0.1, 0.0), "second"),
        (([p], 0.1, math.nan), "second"),
    ):
        with pytest.raises(InputError, match=match):
            hysteresis_jump_bound(*args)
    assert hysteresis_jump_bound([p], 0.0, 1e-3) == 0.0


def test_hysteresis_jump_change_bound_holds_at_every_sample():
    """|j_(k+1) - j_k| <= hysteresis_jump_change_bound over random boxes and inputs whose
    second differences are bounded, once the input has turned; and the bound is below
    the sum of its two parts' largest values (it takes them where they occur)."""
    from bwdesign.model.plant import hysteresis_jump_bound, hysteresis_jump_change_bound

    rng = np.random.default_rng(11)
    worst_share = 0.0
    for _ in range(10):
        _, corners, step, second = _random_box(rng, 0.05)
        jump = hysteresis_jump_bound(corners, step, second)
        change = hysteresis_jump_change_bound(corners, step, second, jump)
        hi = max(c.alpha + (c.beta - c.gamma) * c.bounded_class().h_max for c in corners)
        c_max = max(max(c.beta + c.gamma, c.beta - c.gamma) for c in corners)
        assert 0 < change <= min(2 * jump, hi * second + (1 - math.exp(-c_max * step)) * jump)
        for p in corners[:3]:
            hm = p.bounded_class().h_max
            h, u, last, prev, turned = rng.uniform(-hm, hm), 0.0, None, None, False
            for v in _turning_inputs(rng, step, second, 2000):
                was = turned  # both jumps compared come after the input's first turn
                turned = turned or (prev is not None and prev * v <= 0)
                h1 = hysteresis_increment(p, h, u, u + v)
                if last is not None and was:
                    assert abs((h1 - h) - last) <= change * (1 + 1e-9) + 1e-15
                    worst_share = max(worst_share, abs((h1 - h) - last) / change)
                h, u, last, prev = h1, u + v, h1 - h, v
    assert worst_share > 0.3  # the bound is not vacuous on these inputs
    # the input turning as fast as allowed after a long run at full speed comes close
    exp, sim = preset("paper_experiment"), preset("paper_simulation_corrected")
    # slow turns (the change's own part binds) and fast ones (the turn's hi second binds)
    for p, step, second in ((exp, 0.08, 2.5e-4), (sim, 0.008, 6e-5), (exp, 0.08, 0.02)):
        jump = hysteresis_jump_bound([p], step, second)
        change = hysteresis_jump_change_bound([p], step, second, jump)
        reached = 0.0
        for v0 in np.linspace(-second, 0.0, 6):
            steps = [-step] * int(50 / step) + list(np.arange(-step, v0, second))
            steps += [min(step, v0 + m * second) for m in range(int(2 * step / second) + 5)]
            reached = max(reached, _largest_change(p, steps, int(50 / step)))
        assert 0.6 * change <= reached <= change
    with pytest.raises(InputError, match="bounded plants"):
        hysteresis_jump_change_bound([], 0.1, 1e-3, 0.01)


def _largest_change(p, steps, skip):
    """The largest ``|j_(k+1) - j_k|`` of ``p`` driven from 0 by the input ``steps``,
    after the first ``skip`` of them."""
    h, u, js = 0.0, 0.0, []
    for v in steps:
        h1 = hysteresis_increment(p, h, u, u + v)
        js.append(h1 - h)
        h, u = h1, u + v
    return float(np.max(np.abs(np.diff(js[skip + 1 :]))))
