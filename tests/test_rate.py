"""The robust loop certificate's input-rate envelope proved at a fixed point (prove_rate)."""

from __future__ import annotations

import math

import pytest

from bwdesign import ClosedLoop, UncertaintyBox, certify_robust, load_config
from bwdesign.design import digital_tuning, prove_rate
from bwdesign.errors import InputError

NOMINAL = UncertaintyBox.from_dict({})


def _loop(stage: str, observer: str = "phso"):
    cfg = load_config(stage)
    loop = ClosedLoop.from_config(
        cfg, observer=observer, law=digital_tuning(cfg.plant, cfg.dt), saturate=False
    )
    return cfg, loop


def test_the_stack_loop_proves_its_rate_further_out_at_a_larger_bound():
    cfg, loop = _loop("stack_actuator_800hz")
    udot = cfg.envelope().udot_max
    r = prove_rate(loop, uncertainty=NOMINAL, udot_max=udot, reference=cfg.reference)
    assert r.proved and r.certificate.holds and r.certificate.details["rate_proved"]
    # the proving certificate's own rate bound is within the envelope it assumed
    assert r.certificate.details["input_step_bound"] / cfg.dt <= r.envelope
    assert r.envelope == r.steps[-1][0] and r.steps[0][0] == udot
    # not proved at the stage's envelope: the bound there is tighter, the rate assumed
    at_stage = certify_robust(loop, uncertainty=NOMINAL, udot_max=udot, reference=cfg.reference)
    assert not at_stage.details["rate_proved"] and "assumed, not proved" in at_stage.status
    assert r.certificate.tracking_bound > at_stage.tracking_bound
    assert "proved" in r.certificate.status and r.to_dict()["proved"] is True


def test_a_rate_bound_growing_faster_than_the_envelope_has_no_fixed_point():
    cfg, loop = _loop("paper_simulation_corrected")
    r = prove_rate(
        loop, uncertainty=NOMINAL, udot_max=cfg.envelope().udot_max, reference=cfg.reference
    )
    assert not r.proved and r.reason.startswith("no fixed point")
    assert all(s > e for e, s in r.steps)  # every certificate's rate bound beyond its envelope


def test_with_a_second_difference_envelope_a_fixed_point_exists_close_by():
    """paper_simulation_corrected's rate bound grows faster than its envelope with the jump
    bounded by its largest slope (above); bounded where the input turns, it has a fixed
    point a third above the stage's envelope, and the proving certificate states the
    second-difference envelope as an assumption still."""
    from bwdesign.design import second_envelope
    from bwdesign.sim.falsify import falsify

    cfg, loop = _loop("paper_simulation_corrected")
    udot = cfg.envelope().udot_max
    second = second_envelope(falsify(loop, NOMINAL, cfg.reference).input_accel_max)
    r = prove_rate(
        loop, uncertainty=NOMINAL, udot_max=udot, reference=cfg.reference, uddot_max=second
    )
    assert r.proved and udot < r.envelope < 1.5 * udot
    rc = r.certificate
    assert rc.details["uddot_max"] == second and rc.details["rate_proved"]
    assert "(proved:" in rc.status and "second differences" in rc.status
    assert "(assumed, not proved)" in rc.status


def test_prove_rate_refuses_bad_iterations_and_says_when_it_gave_up():
    cfg, loop = _loop("stack_actuator_800hz")
    kw = dict(uncertainty=NOMINAL, udot_max=cfg.envelope().udot_max, reference=cfg.reference)
    for bad in (0, -1, 1.5, True):
        with pytest.raises(InputError, match="iterations"):
            prove_rate(loop, iterations=bad, **kw)
    r = prove_rate(loop, iterations=1, **kw)
    assert not r.proved and "not proved in 1" in r.reason and len(r.steps) == 1
    assert not math.isnan(r.steps[0][1])
