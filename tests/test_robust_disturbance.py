"""The robust loop certificate with a slowly varying input disturbance (issue 26, Build 3).

The certificate's plant gets ``x2' = ... + a3 (u + d)`` with ``|d| <= input_max`` and
``|d'| <= rate_max`` (:class:`bwdesign.DisturbanceBound`); the brute force runs every
corner of a small box with a sine at the rate limit and a ramp-and-hold through the
simulators' ``input_disturbance``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bwdesign import (
    ClosedLoop,
    DisturbanceBound,
    ObserverSpec,
    Sine,
    Start,
    UncertaintyBox,
    certify_robust,
    preset,
    simulate,
)
from bwdesign.control.controllers import make_controller
from bwdesign.errors import InputError
from bwdesign.observers.gains import disturbance_gains_from
from bwdesign.sim.batch import simulate_batch

DT = 2e-4
PHSO = (786.2, 28982.94, -782.0931942250238)  # the paper stage's digital tuning
LAW = {"lambda1": 250.0, "lambda2": 250.0, "integral_rate": 125.0}
REF = Sine(amplitude=80.0, offset=100.0, frequency=1.0)
UDOT = 80 * 2 * np.pi * 1.1
BOUND = DisturbanceBound(input_max=2.0, rate_max=4.0)  # V, V/s
DURATION = 3.0


def _stage():
    # not a preset: the paper stage with more damping and a weaker hysteresis
    p = preset("paper_experiment")
    return p.replace(a2=1.5 * p.a2, alpha=0.8 * p.alpha, name="custom_stage")


def _loop(p, observer):
    gains = PHSO if observer == "phso" else disturbance_gains_from(PHSO)
    ctrl = make_controller(p, form="discrete", dt=DT, **LAW)
    xd, vd, ad = (float(v[0]) for v in REF.evaluate(np.array([0.0])))
    u0 = float(ctrl.linear_gains()[1] @ np.array([xd, vd, ad]))
    start = Start(x0=(xd, vd, 0.0), xhat0=(xd, vd, 0.0), u_prev=u0)
    return ClosedLoop(p, ObserverSpec(observer, gains), ctrl, dt=DT, delay=True, start=start)


def _signals(bound, t):
    """The worst-case family: a sine at the rate limit and a ramp-and-hold, both signs."""
    dm, rate = bound.input_max, bound.rate_max
    f = rate / (2 * math.pi * dm)  # 2 pi f input_max = rate_max
    sine = dm * np.sin(2 * math.pi * f * t)
    ramp = np.clip(rate * (t - 0.5), 0.0, dm)  # 0 until 0.5 s, up at rate_max, then held
    return [sine, -sine, ramp, -ramp]


@pytest.mark.slow
@pytest.mark.parametrize("observer", ["phso", "phdo"])
def test_disturbed_corners_stay_under_the_certified_bounds(observer):
    p = _stage()
    box = UncertaintyBox.from_dict({"a1": {"rel": 0.02}, "a3": {"rel": 0.02}})
    loop = _loop(p, observer)
    rc = certify_robust(
        loop, uncertainty=box, udot_max=UDOT, reference=REF, interior_samples=2,
        disturbance=BOUND,
    )  # fmt: skip
    assert rc.holds, rc.status
    assert "input disturbance |d| <= 2 V" in rc.status
    assert rc.input_bounds["disturbance"]["input_max"] == BOUND.input_max
    n = round(DURATION / DT)
    sigs = _signals(BOUND, np.arange(n) * DT)
    corners = box.vertices(p)
    plants = [tp for tp in corners for _ in sigs]
    rows = np.array([d for _ in corners for d in sigs])
    assert np.max(np.abs(np.diff(rows, axis=1))) <= BOUND.rate_max * DT * (1 + 1e-12)
    res = simulate_batch(loop, REF, plants, duration=DURATION, input_disturbance=rows)
    assert res.stable.all()
    track = float(np.max(res.maxe))
    est = np.max(res.estimation_maxe, axis=0)
    assert rc.tracking_bound >= track
    assert rc.estimation_bound >= est[0]
    assert rc.x3_estimation_bound >= est[2]  # the PHDO's lumped x3hat + dhat
    # the disturbance is felt: the same corners without it track closer
    calm = simulate_batch(loop, REF, corners, duration=DURATION)
    assert track > float(np.max(calm.maxe))


def test_the_bound_grows_with_input_max_and_none_is_the_old_certificate():
    p = _stage()
    box = UncertaintyBox.from_dict({"a3": {"rel": 0.02}})
    loop = _loop(p, "phso")

    def cert(d):
        return certify_robust(
            loop, uncertainty=box, udot_max=UDOT, reference=REF, interior_samples=0, a=0.99,
            disturbance=d,
        )  # fmt: skip

    none, zero = cert(None), cert(DisturbanceBound(0.0, 0.0))
    assert none.to_dict() == zero.to_dict()  # a bound of 0 and 0 is no disturbance
    assert "disturbance" not in none.input_bounds
    bounds = [cert(DisturbanceBound(dm, 4.0)) for dm in (0.5, 4.0)]
    assert all(b.holds for b in bounds)
    for key in ("tracking_bound", "estimation_bound", "x3_estimation_bound"):
        vals = [getattr(none, key)] + [getattr(b, key) for b in bounds]
        assert all(a < b for a, b in zip(vals, vals[1:], strict=False)), (key, vals)


def test_a_disturbance_that_is_not_a_bound_is_refused():
    p = _stage()
    box = UncertaintyBox.from_dict({"a3": {"rel": 0.02}})
    with pytest.raises(InputError, match="DisturbanceBound"):
        certify_robust(
            _loop(p, "phso"), uncertainty=box, udot_max=UDOT, reference=REF,
            disturbance={"input_max": 1.0},
        )  # fmt: skip


def test_simulate_and_the_batch_apply_the_same_input_disturbance():
    p = _stage()
    loop = _loop(p, "phdo")
    tp = p.replace(a3=1.02 * p.a3)
    n = round(1.0 / DT)
    d = _signals(BOUND, np.arange(n) * DT)[0]
    one = simulate(loop, REF, duration=1.0, true_params=tp, input_disturbance=lambda t: d)
    gen = simulate(loop, REF, duration=1.0, true_params=tp, input_disturbance=d, fast=False)
    batch = simulate_batch(loop, REF, [tp, tp], duration=1.0, input_disturbance=[d, 0 * d])
    assert one.metrics.maxe == pytest.approx(batch.maxe[0], rel=1e-9)
    assert gen.metrics.maxe == pytest.approx(one.metrics.maxe, rel=1e-6)
    plain = simulate(loop, REF, duration=1.0, true_params=tp)
    assert plain.metrics.maxe == pytest.approx(batch.maxe[1], rel=1e-9)
    assert one.settings["input_disturbance_max"] == pytest.approx(np.max(np.abs(d)))
    # the plant moved by the disturbance: x1 differs from the undisturbed run
    assert np.max(np.abs(one.x[:, 0] - plain.x[:, 0])) > 1e-3
    with pytest.raises(InputError, match="shape"):
        simulate(loop, REF, duration=1.0, input_disturbance=d[:-1])
    with pytest.raises(InputError, match="finite"):
        simulate(loop, REF, duration=1.0, input_disturbance=np.full(n, np.nan))


def _observer_beside(model, plant, u, d):
    """The sampled PHSO on the model beside a plant whose linear part sees ``u + d``."""
    from bwdesign import HysteresisObserver
    from bwdesign.model.plant import discretize, zoh_step

    x = np.array([plant.a3 * (u[0] + d[0]) / plant.a1, 0.0, 0.0])  # at rest, x3 = 0
    obs = HysteresisObserver(model, gains=PHSO, dt=DT, x0=x.copy(), u_prev=u[0])
    gv = np.asarray(discretize(plant, DT).g)
    worst, u_prev = np.zeros(3), u[0]
    for uk, dk in zip(u, d, strict=True):
        xn = zoh_step(plant, x, u_prev, uk, DT) + gv * dk  # the hysteresis sees u only
        obs.predict(uk)
        obs.update(xn[0])
        worst = np.maximum(worst, np.abs(obs.x - xn))
        x, u_prev = xn, uk
    return worst


def test_observer_certificate_with_a_disturbance_covers_the_brute_force():
    from bwdesign import BoxSampling, certify_robust_observer

    p = _stage()
    box = UncertaintyBox.from_dict({"a3": {"rel": 0.02}})
    rng_u = (0.0, 150.0)
    kw = dict(dt=DT, uncertainty=box, udot_max=UDOT, input_range=rng_u, a=0.97)
    kw |= {"sampling": BoxSampling(0)}
    calm = certify_robust_observer(p, PHSO, **kw)
    rc = certify_robust_observer(p, PHSO, disturbance=BOUND, **kw)
    assert calm.holds and rc.holds, rc.status
    assert "input disturbance |d| <= 2" in rc.status
    assert rc.estimation_bound > calm.estimation_bound
    assert rc.x3_estimation_bound > calm.x3_estimation_bound
    n = round(1.0 / DT)
    t = np.arange(n) * DT
    u = 75.0 + 70.0 * np.sin(2 * math.pi * 1.0 * t)  # |u'| = 440 V/s <= UDOT
    assert np.max(np.abs(np.diff(u))) <= UDOT * DT
    worst = np.zeros(3)
    for tp in box.vertices(p):
        for d in _signals(BOUND, t):
            worst = np.maximum(worst, _observer_beside(p, tp, u, d))
    assert rc.estimation_bound >= worst[0] > 0
    assert rc.x3_estimation_bound >= worst[2] > 0
    # None and a zero bound are the certificate without a disturbance
    zero = certify_robust_observer(p, PHSO, disturbance=DisturbanceBound(0.0, 0.0), **kw)
    assert zero.to_dict() == calm.to_dict()


def test_worst_case_and_sweep_signals_keep_the_bound():
    from bwdesign.sim.corners import disturbance_signals
    from bwdesign.sim.sweep import scenario_disturbance

    t = np.arange(20000) * DT
    for bound in (BOUND, DisturbanceBound(0.5, 0.0), DisturbanceBound(0.0, 3.0)):
        for rows in (disturbance_signals(bound, t), scenario_disturbance(bound, [1, 2, 3], t)):
            assert np.max(np.abs(rows)) <= bound.input_max * (1 + 1e-12)
            step = np.max(np.abs(np.diff(rows, axis=1)))
            assert step <= bound.rate_max * DT * (1 + 1e-9)
    rows = scenario_disturbance(BOUND, [1, 2, 1], t)
    assert np.array_equal(rows[0], rows[2]) and not np.array_equal(rows[0], rows[1])  # seeded
    assert np.max(np.abs(disturbance_signals(BOUND, t))) == pytest.approx(BOUND.input_max)


def test_the_sweep_reads_the_stage_disturbance():
    import dataclasses

    from bwdesign import load_config
    from bwdesign.sim.sweep import draw_scenarios, run_chunk, spec_from_config

    cfg = load_config("configs/stack_actuator_800hz.toml")
    assert cfg.disturbance is None  # the bundled stages carry none
    plain = spec_from_config(cfg, observers=("phso",), duration=0.5)
    assert plain.disturbance is None
    bound = DisturbanceBound(1.0, 20.0)
    spec = spec_from_config(
        dataclasses.replace(cfg, disturbance=bound), observers=("phso",), duration=0.5
    )
    assert spec.disturbance == bound
    cols = draw_scenarios(spec.params, spec.box, 3, seed=4)
    a, b = run_chunk(plain, cols), run_chunk(spec, cols)
    assert np.all(a["stable"]) and np.all(b["stable"])
    assert not np.allclose(a["maxe"], b["maxe"])  # the disturbance moved the plant
    assert np.array_equal(b["maxe"], run_chunk(spec, cols)["maxe"])  # and is seeded
