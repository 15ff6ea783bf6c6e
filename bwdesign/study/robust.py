"""The study's robust section: certificates over ``[uncertainty]`` beside the simulated corners.

For the digital tuning's loop (its eq. (12) constants, integral rate and
compensated delay) with the PHSO and with the disturbance observer (PHDO, the
tuning's ``(l1, l2, 0, l3)``): :func:`bwdesign.certify_robust` over every corner
of the box, beside the worst error :func:`bwdesign.sim.simulate_batch` finds at
those corners. Like for like, the simulated columns are steady-state max
``|error|`` (tracking, ``x1`` and ``x3`` estimates; the PHDO's ``x3`` is the
lumped ``x3hat + dhat``) over the batch's metrics window (the last two reference
periods), as the certified bounds are peak bounds after the transient.

A robust certificate assumes the loop keeps ``|u'| <= udot_max`` and does not
prove it: the corners are simulated first, and when their input moves faster than
the stage's envelope the certificate is asked for
:func:`bwdesign.design.certified_envelope` of their fastest rate. It also assumes a
second-difference envelope, :func:`bwdesign.design.second_envelope` of the largest
the falsifier's plants show, which bounds the plant's hysteresis jump more tightly
(:func:`bwdesign.model.plant.hysteresis_jump_bound`); the verdict states both. Where the
certificate's own bound on the input rate is within 10 % of its envelope, it is asked
once more at that bound, and kept there if it proves it with the same tracking bound
(within 1 %): the rate is then shown, not assumed.

A stage with ``[uncertainty.disturbance]`` (``StageConfig.disturbance``) has it in
the certificate (``certify_robust(..., disturbance=)``) and in the corners'
simulation: each corner runs :func:`bwdesign.sim.corners.disturbance_signals` (a
sine at the rate limit and a ramp-and-hold, both signs).
"""

from __future__ import annotations

import math
from functools import partial
from typing import Any

import numpy as np

from ..certify.robust import certify_robust
from ..control.loop import ClosedLoop
from ..design.robust import certified_envelope, second_envelope
from ..design.tuning import DigitalTuning
from ..errors import InternalError
from ..model.config import StageConfig
from ..model.uncertainty import DisturbanceBound, UncertaintyBox
from ..sim.falsify import falsify
from . import background
from .result import RobustLoop, RobustStudy

__all__ = [
    "robust_study",
    "begin_robust_study",
    "robust_loop",
    "stage_disturbance",
    "ROBUST_OBSERVERS",
]

#: The falsifier's search beside each certificate (:func:`bwdesign.sim.falsify.falsify`).
#: 64 interior plants and 6 rounds of 16 (224 plants with the 64 corners of a six-parameter
#: box): a fraction of a second with the compiled batch. On the bundled stages' boxes and
#: +-5 % boxes the worst found stays at a corner but for one row (paper_simulation_corrected
#: +-5 % PHSO: 0.639 at the corners, 0.644 here, 0.656 with 640 plants).
FALSIFIER = {"interior": 64, "rounds": 6, "per_round": 16, "seed": 0}
#: A certificate whose own bound on the input rate is at most 1 / PROVE_NEARBY times the
#: envelope it assumed is asked again at that bound (:func:`_proved_nearby`).
PROVE_NEARBY = 0.9
#: The observers of the robust section, in table order.
ROBUST_OBSERVERS = ("phso", "phdo")


def stage_disturbance(config: StageConfig) -> DisturbanceBound | None:
    """The stage's ``[uncertainty.disturbance]`` bound the robust section carries (None:
    none stated, or stated as none)."""
    d = config.disturbance
    return d if d and not d.none else None


def robust_loop(
    config: StageConfig,
    tuning: DigitalTuning,
    udot_max: float,
    observer: str,
    box: UncertaintyBox | None = None,
) -> RobustLoop:
    """One observer's robust certificate over ``box`` (default ``[uncertainty]``; an
    empty box is the nominal plant alone) beside the falsifier's worst case (noise free)."""
    box = config.uncertainty if box is None else box
    ref = config.reference
    gains = tuning.observer_gains_for(observer)
    loop = ClosedLoop.from_config(config, observer=observer, law=tuning, saturate=False)
    dist = stage_disturbance(config)
    found = falsify(loop, box, ref, disturbance=dist, **FALSIFIER)
    stable = found.stable
    rate = found.input_rate_max if stable else math.nan
    env = certified_envelope(udot_max, rate) if stable else udot_max
    second = second_envelope(found.input_accel_max) if stable else None
    kw = {"uncertainty": box, "reference": ref, "disturbance": dist, "uddot_max": second}
    rc = certify_robust(loop, udot_max=env, **kw)
    rc, env = _proved_nearby(loop, rc, env, kw)
    worst = found.worst_maxe if stable else math.nan
    worst_est = np.array(found.worst_estimation_maxe) if stable else np.full(3, math.nan)
    if rc.holds:
        _require_sound(rc, worst, worst_est, observer)
    ratio = rc.tracking_bound / worst if rc.holds and worst > 0 else None
    return RobustLoop(
        observer=observer,
        gains=tuple(gains),
        certificate=rc,
        envelope=env,
        simulated_input_rate_max=rate,
        simulated_worst_maxe=worst,
        simulated_worst_estimation_maxe=tuple(worst_est.tolist()),
        simulated_window=tuple(found.window),
        samples=found.samples,
        all_corners_stable=stable,
        conservatism=ratio,
        found=found,
    )


def _proved_nearby(loop: ClosedLoop, rc, env: float, kw: dict) -> tuple[Any, float]:
    """The certificate at the envelope its own rate bound gives, where that bound is within
    :data:`PROVE_NEARBY` of ``env``: kept if it proves that envelope (a fixed point: the
    rate is then shown, not assumed) with a tracking bound within 1 % of ``rc``'s; else
    ``rc`` at ``env`` (one more certificate at most)."""
    d = rc.details
    if not rc.holds or d["rate_proved"] or not (d["rate_margin"] or 0) >= PROVE_NEARBY:
        return rc, env
    near = 1.001 * d["input_step_bound"] / d["dt"]
    proved = certify_robust(loop, udot_max=near, **kw)
    if proved.holds and proved.details["rate_proved"]:
        if proved.tracking_bound <= 1.01 * rc.tracking_bound:
            return proved, near
    return rc, env


def _require_sound(rc, worst: float, worst_est: np.ndarray, observer: str) -> None:
    """A found case above a certified bound is a defect, never a report."""
    for what, b, w in (
        ("tracking", rc.tracking_bound, worst),
        ("x1 estimation", rc.estimation_bound, worst_est[0]),
        ("x3 estimation", rc.x3_estimation_bound, worst_est[2]),
    ):
        if b is not None and w > b * (1 + 1e-9):  # the bound is floored at rounding
            raise InternalError(
                f"the {observer} robust certificate's {what} bound {b:.6g} is below a case "
                f"the falsifier found ({w:.6g}): the certificate is wrong"
            )


def robust_study(
    config: StageConfig, tuning: DigitalTuning, udot_max: float, *, workers: int = 1
) -> RobustStudy:
    """The robust section of ``config`` (over its ``[uncertainty]`` box where determined,
    and of the nominal loop).

    The certified bounds are noise free (``noise_max = 0``) and so is the vertex
    simulation, so the two compare the same loops. ``workers >= 2``: two forked
    children certify every second loop each (:func:`bwdesign.study.background.split`;
    the same section, in about half the time where the loops weigh alike, and a box's
    solves, 50-70 MB each on the stack's, are not added to this process's memory).
    """
    return begin_robust_study(config, tuning, udot_max, workers=workers).result()


def begin_robust_study(
    config: StageConfig, tuning: DigitalTuning, udot_max: float, *, workers: int = 1
) -> background.Pending:
    """:func:`robust_study` begun: with ``workers >= 2`` the children are at work when it
    returns, while the caller goes on; its ``result()`` (called once) waits for them and
    gives the section. Without children the section is computed then."""
    box = config.uncertainty
    has_box = box is not None and not box.undetermined()
    nominal = UncertaintyBox.from_dict({})
    boxes = ((("box", None),) if has_box else ()) + (("nominal", nominal),)
    tasks = [
        (f"{obs} {name}", partial(robust_loop, config, tuning, udot_max, obs, b))
        for name, b in boxes
        for obs in ROBUST_OBSERVERS
    ]
    begun = background.Split(tasks, here=False) if workers >= 2 else None

    def section() -> RobustStudy:
        loops = begun.values() if begun is not None else [task() for _, task in tasks]
        n = len(ROBUST_OBSERVERS)
        return RobustStudy(
            udot_max=udot_max,
            bounds=box.bounds(config.plant) if has_box else {},
            loops=tuple(loops[:-n]),
            disturbance=stage_disturbance(config),
            nominal=tuple(loops[-n:]),
        )

    return background.Pending(section, begun.close if begun is not None else lambda: None)
