"""``bwdesign synthesize --robust``: the tracking loop designed against ``[uncertainty]``.

Needs a stage file with ``[uncertainty]`` (finite half-widths), ``[reference]``,
``[sampling]`` dt and an envelope (``[envelope]`` or ``--udot-max``). Exit 0
with a certified design, 1 when no candidate is certified over the box.
"""

from __future__ import annotations

import argparse

from ..design.robust import RobustDesign, synthesize_robust
from ..output.jsonenc import dump_json
from .args import EXIT_NO, EXIT_OK, UsageError
from .stage import Stage

__all__ = ["run_robust"]


def _require(stage: Stage) -> None:
    cfg = stage.config
    missing = []
    if cfg is None:
        raise UsageError(
            "--robust needs --plant to be a stage file with [uncertainty], [reference] and "
            "[sampling] sections (a preset name has none)"
        )
    if cfg.uncertainty is None:
        missing.append("[uncertainty]")
    if cfg.reference is None:
        missing.append("[reference]")
    if missing:
        raise UsageError(f"{cfg.source}: --robust needs {' and '.join(missing)}")
    cfg.uncertainty.check(stage.params)  # finite, every corner a bounded plant


def _print(design: RobustDesign, stage: Stage) -> None:
    p = stage.params
    lu, iu = p.length_unit, p.input_unit
    widths = stage.config.uncertainty.describe(p)
    print(
        f"plant: {p.name or '(unnamed)'}   observer: {design.observer}   robust design over "
        f"the box: {widths}"
    )
    print(
        f"{'omega_o (rad/s)':>15} {'lambda (1/s)':>12} {'margins':>8} {'holds':>6} "
        f"{'|x1-x_d| <=':>12} {'|x1hat-x1| <=':>14} {'|x3hat-x3| <=':>14} "
        f"{'sim |x1-x_d|':>13} {'sim |du/dt|':>12} {'envelope':>9}  origin"
    )

    def num(x, fmt=".4g"):
        return "-" if x is None else format(x, fmt)

    for c in design.candidates:
        print(
            f"{num(c['observer_bandwidth']):>15} {num(c['lambda']):>12} "
            f"{num(c['score'], '.3g'):>8} "
            f"{'yes' if c['holds'] else 'no':>6} {num(c['tracking_bound']):>12} "
            f"{num(c['estimation_bound']):>14} {num(c['x3_estimation_bound']):>14} "
            f"{num(c['simulated_maxe']):>13} {num(c['simulated_udot_max']):>12} "
            f"{num(c['envelope']):>9}  "
            f"{c['origin']}"
        )
    print(
        f"(bounds and simulated errors in {lu}, rates in {iu}/s; margins = worst-case min(GM, "
        "PM, DM) score over the box, >= 1 meets; sim = the worst over the box's corners, "
        "started on the reference, after the first period; envelope = the |u'| the certificate "
        "assumes: the stage's, or 1.1 x the simulated rate when that is faster)"
    )
    if design.feasible:
        rc = design.certificate
        print(f"gains l = {', '.join(f'{g:.8g}' for g in design.gains)}")
        print(
            f"lambda1 = lambda2 = {design.lambda1:.8g} 1/s, integral rate "
            f"{design.integral_rate} 1/s, delay {'on' if design.delay else 'off'}"
        )
        print(f"robust: yes ({design.reason}): {rc.status}")
    else:
        print(f"robust: no: {design.reason}")


def run_robust(args: argparse.Namespace, stage: Stage) -> int:
    """Run the robust design for ``bwdesign synthesize --robust``."""
    _require(stage)
    cfg = stage.config
    if args.dt is None:
        raise UsageError("--robust needs a sample time: --dt or [sampling] dt")
    design = synthesize_robust(
        stage.params,
        dt=args.dt,
        uncertainty=cfg.uncertainty,
        udot_max=args.udot_max,
        reference=cfg.reference,
        noise_max=args.noise_max or 0.0,
        observer=args.observer or "phdo",
    )
    if args.json:
        doc = {"robust_design": design.to_dict(), "udot_max": args.udot_max}
        if stage.to_dict() is not None:
            doc["defaults_from_file"] = stage.to_dict()
        print(dump_json(doc))
    else:
        note = stage.note()
        if note is not None:
            print(note)
        _print(design, stage)
    return EXIT_OK if design.feasible else EXIT_NO
