"""The robust loop certificate covers the whole reference, at every time (issue 24, item 0).

It used to evaluate a reference that is not periodic over [0, 2 s] only, so a step
three seconds in was never seen and its bound was broken 7-10x by the simulation
of every corner. Now every reference term is bounded over every t >= 0
(:func:`bwdesign.model.reference_cover.sup_abs`), or the reference is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from bwdesign import (
    ClosedLoop,
    ObserverSpec,
    Sine,
    Start,
    Step,
    Triangle,
    UncertaintyBox,
    certify_robust,
    preset,
)
from bwdesign.control.controllers import make_controller
from bwdesign.control.loop import ON_REFERENCE
from bwdesign.errors import InputError
from bwdesign.model.reference_cover import SIGMA, sup_abs
from bwdesign.model.references import Reference
from bwdesign.sim.batch import simulate_batch


@dataclass(frozen=True)
class LateMove(Reference):
    """A user's own reference: a raised-cosine move of ``amplitude`` from ``t0`` over ``T``."""

    amplitude: float
    t0: float
    T: float

    @property
    def settles_at(self):
        return self.t0 + self.T

    def _s(self, t):
        return np.clip((np.asarray(t, float) - self.t0) / self.T, 0.0, 1.0)

    def evaluate(self, t):
        s, w = self._s(t), math.pi / self.T
        inside = (s > 0) & (s < 1)
        A = self.amplitude
        return (
            A * (1 - np.cos(math.pi * s)) / 2,
            np.where(inside, A * w * np.sin(math.pi * s) / 2, 0.0),
            np.where(inside, A * w * w * np.cos(math.pi * s) / 2, 0.0),
        )

    def jerk(self, t):
        s, w = self._s(t), math.pi / self.T
        return np.where((s > 0) & (s < 1), -self.amplitude * w**3 * np.sin(math.pi * s) / 2, 0.0)

    def breakpoints(self, t0, t1):
        pts = np.array([self.t0, self.t0 + self.T])
        return pts[(pts >= t0) & (pts <= t1)]

    def derivative_bounds(self, t0, t1):
        if t1 <= self.t0 or t0 >= self.t0 + self.T:
            return (0.0, 0.0, 0.0, 0.0)
        w, A = math.pi / self.T, abs(self.amplitude) / 2
        return (A * w, A * w * w, A * w**3, A * w**4)

    def to_dict(self):
        return {"kind": "late_move", "amplitude": self.amplitude, "t0": self.t0, "T": self.T}

    def describe(self):
        return f"raised-cosine move of {self.amplitude:g} at {self.t0:g} s over {self.T:g} s"


class Unstated(Reference):
    """A reference that says nothing about its structure: can be simulated, not certified."""

    def evaluate(self, t):
        t = np.asarray(t, float)
        return np.sin(t), np.cos(t), -np.sin(t)


DT = 2e-4
GAINS = (786.2, 28982.94, -782.0931942250238)  # the paper stage's digital tuning
LOOP = {"lambda1": 250.0, "lambda2": 250.0, "integral_rate": 125.0}

REFERENCES = [
    Sine(amplitude=7.0, offset=8.0, frequency=10.0, phase=0.3),
    Triangle(amplitude=7.0, offset=8.0, frequency=10.0, corner_time=0.002),
    Triangle(amplitude=7.0, offset=8.0, frequency=3.0),
    Step(amplitude=15.0, t_step=3.0, rise_time=0.5),
    Step(amplitude=-4.0, offset=2.0, t_step=0.70001),
    Step(amplitude=5.0, t_step=-0.2, rise_time=0.5),
    LateMove(amplitude=3.0, t0=2.5, T=0.2),
]


def _sigma(ref, t, dt):
    return np.array([np.asarray(v) for s in (0, dt, 2 * dt) for v in ref.evaluate(t + s)])


@pytest.fixture(scope="module")
def loop_rows():
    """The rows certify_robust builds for the paper stage's tuned loop: nearly cancelling
    combinations (a second difference of x_d against x_d'), where a first-order margin
    was 22 % of the value. Captured once, by a spy in place of ``sup_abs``; nothing kept
    (bwdesign.memo) hides the spy or outlives it."""
    import importlib

    from bwdesign.memo import clear_all

    robust = importlib.import_module("bwdesign.certify.robust_cover")
    captured = {}

    def spy(reference, dt, L, **kw):
        captured["L"] = L
        raise RuntimeError("captured")

    with pytest.MonkeyPatch.context() as mp:
        clear_all()
        mp.setattr(robust, "sup_abs", spy)
        # the worst case per sample, as a fallback
        mp.setattr(robust, "response_sups", lambda *a, **k: None)
        with pytest.raises(RuntimeError, match="captured"):
            certify_robust(
                _loop(preset("paper_experiment")), uncertainty=UncertaintyBox.from_dict(
                    {"a3": {"rel": 0.02}}), udot_max=500.0, reference=Sine(amplitude=80.0,
                offset=100.0, frequency=1.0), interior_samples=0,
            )  # fmt: skip
    clear_all()
    return captured["L"]


@pytest.mark.parametrize("ref", REFERENCES, ids=lambda r: type(r).__name__)
def test_sup_abs_bounds_a_dense_evaluation_at_every_time_and_is_tight(ref, loop_rows):
    dt = 5e-5
    rng = np.random.default_rng(1)
    L = rng.normal(size=(6, 9))
    inc = np.zeros((2, 9))
    inc[0, [3, 0]] = (1.0, -1.0)  # x_d(t + dt) - x_d(t): an increment functional
    inc[1, [7, 4, 1]] = (1.0, -2.0, 1.0)  # second difference of x_d'
    L = np.vstack([L, inc, loop_rows])
    bound = sup_abs(ref, dt, L)
    end = ref.period if ref.period else max(ref.settles_at, 0.0) + 1.0
    t = np.concatenate([np.linspace(0.0, end, 1_000_001), np.arange(0, int(end / dt) + 2) * dt])
    dense = np.zeros(len(L))
    for part in np.array_split(t, 40):  # a few MB at a time, not a 350 MB block
        dense = np.maximum(dense, np.abs(L @ _sigma(ref, part, dt)).max(axis=1))
    assert np.all(bound >= dense), (bound, dense)
    assert np.all(bound <= dense * (1 + 2e-3) + 1e-12), bound / dense  # tight


def test_sup_abs_sees_a_late_step_that_a_window_misses():
    dt = 2e-4
    ref = Step(amplitude=150.0, offset=10.0, t_step=3.0, rise_time=0.5)
    inc = np.zeros((1, 9))
    inc[0, [3, 0]] = (1.0, -1.0)
    window = np.abs(np.diff(ref.evaluate(np.arange(0, 2.0, dt))[0])).max()
    assert window == 0.0
    assert sup_abs(ref, dt, inc)[0] >= 150.0 * 1.875 / 0.5 * dt * (1 - 1e-3)


def test_a_reference_that_cannot_be_covered_is_refused():
    with pytest.raises(InputError, match="does not state its breakpoints"):
        sup_abs(Unstated(), 1e-3, np.ones((1, len(SIGMA))))
    box = UncertaintyBox.from_dict({"a3": {"rel": 0.02}})
    with pytest.raises(InputError, match="does not state its breakpoints"):
        _certify(preset("paper_experiment"), box, Unstated(), interior_samples=0, a=0.99)


class Drifting(LateMove):
    @property
    def settles_at(self):
        return None


def test_a_reference_that_neither_repeats_nor_settles_is_refused():
    with pytest.raises(InputError, match="neither periodic"):
        sup_abs(Drifting(amplitude=1.0, t0=0.0, T=1.0), 1e-3, np.ones((1, 9)))


def _loop(params, start=ON_REFERENCE):
    ctrl = make_controller(params, form="discrete", dt=DT, **LOOP)
    return ClosedLoop(params, ObserverSpec.of("phso", GAINS), ctrl, dt=DT, delay=True, start=start)


def _certify(params, box, ref, **kw):
    udot_max = kw.pop("udot_max", 600.0)
    return certify_robust(_loop(params), uncertainty=box, udot_max=udot_max, reference=ref, **kw)


def _corners(params, box, ref, duration):
    loop = _loop(params, Start.on_reference(params, ref))
    res = simulate_batch(loop, ref, box.vertices(params), duration=duration, window=(0.5, duration))
    assert res.stable.all()
    return res


@pytest.mark.parametrize(
    "ref",
    [
        Step(amplitude=150.0, offset=10.0, t_step=3.0, rise_time=0.5),  # late
        Step(amplitude=150.0, offset=10.0, t_step=1.8, rise_time=0.5),  # straddles 2 s
        LateMove(amplitude=120.0, t0=2.2, T=0.4),  # a user's own class, late
    ],
    ids=["late-step", "straddling-step", "custom-class"],
)
def test_the_bound_covers_every_corner_after_a_late_move(ref):
    p = preset("paper_experiment")
    box = UncertaintyBox.from_dict({"a1": {"rel": 0.02}, "a3": {"rel": 0.02}})
    res = _corners(p, box, ref, duration=ref.settles_at + 1.0)
    # a fixed contraction keeps it quick; before the fix the x3 bound was 1.83 (late step)
    # and 5.38 (straddling) against 6.52 simulated
    rate = 1.1 * np.max(res.input_rate_max)
    rc = _certify(p, box, ref, interior_samples=0, udot_max=rate, a=0.99)
    assert rc.holds, rc.status
    assert rc.tracking_bound >= np.max(res.maxe) > 0
    assert rc.estimation_bound >= np.nanmax(res.estimation_maxe[:, 0])
    assert rc.x3_estimation_bound >= np.nanmax(res.estimation_maxe[:, 2])


@pytest.mark.slow
@pytest.mark.parametrize("observer", ["phso", "phdo"])
def test_the_reports_loop_on_the_stack_stage_with_a_late_step(observer):
    """The audit's case: the report's loop (digital tuning, integral action, compensated
    delay), the stage's own 64-corner box, a 0 -> 15 um step at 3 s with a 0.5 s rise,
    the envelope by the stage's rule. Before: x3 bound 0.0898 (PHDO) / 0.0702 (PHSO)
    against 0.675 simulated after the step."""
    from bwdesign.design.tuning import digital_tuning
    from bwdesign.model.config import load_config
    from bwdesign.model.envelope import derive_envelope
    from bwdesign.sim import simulate_corners

    cfg = load_config("configs/stack_actuator_800hz.toml")
    p, dt, box = cfg.plant, float(cfg.dt), cfg.uncertainty
    ref = Step(amplitude=15.0, t_step=3.0, rise_time=0.5)
    tun = digital_tuning(p, dt)
    gains = tun.observer_gains_for(observer)
    loop = {"lambda1": tun.lambda1, "lambda2": tun.lambda2, "integral_rate": tun.integral_rate}
    ctrl = make_controller(p, form="discrete", dt=dt, **loop)
    spec = ObserverSpec.of(observer, tun.gains)
    assert spec.gains == gains
    cl = ClosedLoop(p, spec, ctrl, dt=dt, delay=tun.delay, start=ON_REFERENCE)
    sim = simulate_corners(cl, box, ref)
    # the statistics from the step's first move on (to 1 s after it has settled)
    assert sim.window[0] <= ref.t_step < ref.settles_at < sim.window[1]
    env = derive_envelope(p, ref, margin=1.1).udot_max
    assert np.max(sim.input_rate_max) <= env
    rc = certify_robust(cl, uncertainty=box, udot_max=env, reference=ref)
    assert rc.holds, rc.status
    assert rc.tracking_bound >= np.max(sim.maxe)
    assert rc.estimation_bound >= np.nanmax(sim.estimation_maxe[:, 0])
    assert rc.x3_estimation_bound >= np.nanmax(sim.estimation_maxe[:, 2]) > 0.5


def test_a_reference_above_nyquist_is_refused():
    box = UncertaintyBox.from_dict({"a3": {"rel": 0.02}})
    with pytest.raises(InputError, match="Nyquist"):
        _certify(preset("paper_experiment"), box, Sine(amplitude=1.0, frequency=3000.0))
