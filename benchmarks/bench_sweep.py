"""Scenario-steps per second of the batched loop, beside simulate() and a solve_ivp reference.

Usage::

    .venv/bin/python benchmarks/bench_sweep.py [--scenarios 10000] [--sweep 10000] [--json FILE]

On ``paper_experiment`` with the digital tuning (PHSO, dt = 0.2 ms, 1 Hz sine,
0.02 um noise, +-2 % / +-10 % parameter box), in one process:

- the batched loop (:func:`bwdesign.sim.batch.simulate_batch`) over ``--scenarios``
  scenarios for 1 s, setup included (one core: numpy is single-threaded here);
- the scalar :func:`bwdesign.simulate` (fast path) on one scenario;
- a ``scipy.integrate.solve_ivp`` reference: the same sampled loop with the plant
  integrated between samples (Radau, rtol 1e-10, atol 1e-12 um) instead of the
  exact ZOH step, on a few hundred samples; its accuracy against the exact step is
  printed beside it;
- the wall time of a ``--sweep``-scenario, 1-second sweep (``bwdesign sweep``'s
  runner) on a LocalCluster of 1 and of 2 worker processes. Targets: >= 2e7
  scenario-steps/s for the batched PHSO loop on one core (printed beside the scalar
  loop, the reference run in the same process), and the 2-worker sweep faster than
  the 1-worker one.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from bwdesign import (
    ClosedLoop,
    DiscreteTrackingController,
    ObserverSpec,
    Sine,
    UncertaintyBox,
    digital_tuning,
    preset,
    simulate,
)
from bwdesign.control.loop import ON_REFERENCE
from bwdesign.model.plant import hysteresis_increment, zoh_step
from bwdesign.sim.batch import simulate_batch
from bwdesign.sim.sweep import SweepSpec, draw_scenarios, run_sweep

DT = 2e-4
TARGET = 2e7
BOX = UncertaintyBox.parse("a1=2%,a2=2%,a3=2%,alpha=10%,beta=10%,gamma=10%")


def _setup():
    p = preset("paper_experiment")
    tune = digital_tuning(p, DT)
    ctl = DiscreteTrackingController(
        p, tune.lambda1, tune.lambda2, dt=DT, integral_rate=tune.integral_rate
    )
    loop = ClosedLoop(p, ObserverSpec.of("phso", tune.gains), ctl, dt=DT)
    return p, tune, loop, Sine(amplitude=80, offset=100, frequency=1)


def batched(n: int) -> float:
    p, _, loop, ref = _setup()
    cols = draw_scenarios(p, BOX, n, seed=0)
    tps = [replace(p, **{k: float(cols[k][i]) for k in BOX.widths}) for i in range(n)]
    duration = 1.0
    t0 = time.perf_counter()
    res = simulate_batch(
        loop, ref, tps, duration=duration, noise_std=0.02, seeds=cols["noise_seed"]
    )
    return n * res.samples / (time.perf_counter() - t0)


def scalar() -> float:
    _, _, loop, ref = _setup()
    t0 = time.perf_counter()
    simulate(loop, ref, duration=1.0, noise_std=0.02)
    return 5000 / (time.perf_counter() - t0)


def ivp(steps: int = 300) -> tuple[float, float]:
    """The plant's linear part integrated with Radau between samples; open loop, held input."""
    p, *_ = _setup()
    u = 70 + 60 * np.sin(2 * np.pi * np.arange(steps) * DT)
    x = np.zeros(3)
    xe = np.zeros(3)
    up = 0.0
    t0 = time.perf_counter()
    for uk in u:
        h = hysteresis_increment(p, x[2], up, uk)

        def f(_t, y, h=h, uk=uk):
            return [y[1], -p.a1 * y[0] - p.a2 * y[1] - p.a1 * h + p.a3 * uk]

        sol = solve_ivp(f, (0, DT), [x[0], x[1]], method="Radau", rtol=1e-10, atol=1e-12)
        x = np.array([sol.y[0, -1], sol.y[1, -1], h])
        xe = zoh_step(p, xe, up, uk, DT)
        up = uk
    rate = steps / (time.perf_counter() - t0)
    return rate, float(abs(x[0] - xe[0]) / max(abs(xe[0]), 1e-12))


def sweep_time(n: int, workers: int) -> float:
    p, tune, loop, ref = _setup()
    spec = SweepSpec(
        loop=loop.replace(start=ON_REFERENCE),  # as every sweep: started on the reference
        reference=ref,
        duration=1.0,
        gains=tuple(tune.gains),
        observers=("phso",),
        noise_std=0.02,
        box=BOX,
    )
    sc = draw_scenarios(p, BOX, n, seed=0)
    t0 = time.perf_counter()
    run_sweep(spec, sc, chunk_size=max(1, n // (2 * workers)), workers=workers)
    return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", type=int, default=10_000)
    ap.add_argument("--sweep", type=int, default=10_000)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    b = max(batched(args.scenarios) for _ in range(2))
    s = max(scalar() for _ in range(2))
    i, err = ivp()
    print(f"sampled PHSO loop, paper_experiment, dt = {DT:g} s")
    print(
        f"  batched ({args.scenarios} scenarios): {b:10.3g} scenario-steps/s "
        f"(target {TARGET:.0e}: {'met' if b >= TARGET else 'NOT met'})"
    )
    print(f"  scalar simulate():          {s:10.3g} steps/s   (batched / scalar = {b / s:.0f}x)")
    print(f"  solve_ivp plant (Radau):    {i:10.3g} steps/s   (x1 relative to exact ZOH {err:.1e})")
    out = {"batched": b, "scalar": s, "solve_ivp": i, "solve_ivp_error": err}
    met = b >= TARGET
    if args.sweep:
        for w in (1, 2):
            out[f"sweep_{w}_workers_s"] = t = sweep_time(args.sweep, w)
            print(f"  sweep of {args.sweep} scenarios x 1 s, {w} worker(s): {t:8.1f} s")
        ratio = out["sweep_1_workers_s"] / out["sweep_2_workers_s"]
        print(
            f"  2 workers / 1 worker speed-up: {ratio:.2f}x (target > 1: "
            f"{'met' if ratio > 1 else 'NOT met'})"
        )
        met = met and ratio > 1
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
