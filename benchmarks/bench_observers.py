"""Per-step cost of the observers beside filterpy's KalmanFilter and the UKF.

Usage::

    .venv/bin/python benchmarks/bench_observers.py [--reps 9] [--steps 2000] [--json FILE]

Measures, in one process on the experiment stage (``paper_experiment``, dt = 0.2 ms,
gains (8, 64, -512)) with a seeded record (1 Hz sine input, noisy measurements):

- ``predict(u)`` + ``update(z)`` time per step of the PHSO, the ESO, filterpy's
  ``KalmanFilter`` (dim_x = 3, dim_z = 1, with the ZOH matrices as F and a B
  matrix for the held input), the UKF baseline, and the PHSO's plain-function
  twin ``phso_step``. Repetitions are interleaved (each repetition runs every
  filter once, in rotating order) and the median over repetitions is reported,
  with the spread (min..max).
- ``batch_filter`` throughput in steps per second (PHSO, ESO, UKF).

Prints a table on stdout; writes nothing unless ``--json FILE`` is given.
"""

from __future__ import annotations

import argparse
import gc
import json
import platform
import statistics
import sys
import time

import numpy as np
from filterpy.kalman import KalmanFilter

from bwdesign import (
    ExtendedStateObserver,
    HysteresisObserver,
    UnscentedObserver,
    preset,
    simulate_zoh,
)
from bwdesign.model.plant import discretize
from bwdesign.observers.dynamics import phso_step

DT = 2e-4
GAINS = (8.0, 64.0, -512.0)


def record(n: int, seed: int = 0) -> tuple[np.ndarray, list[float]]:
    p = preset("paper_experiment")
    t = np.arange(n) * DT
    u = 70.0 + 60.0 * np.sin(2 * np.pi * t)
    X = simulate_zoh(p, u, DT, (0.0, 0.0, 0.0), u_prev=float(u[0]))
    z = X[1:, 0] + 0.01 * np.random.default_rng(seed).standard_normal(n)
    return u, z.tolist()


def make_kf():
    p = preset("paper_experiment")
    zoh = discretize(p, DT)
    kf = KalmanFilter(dim_x=3, dim_z=1, dim_u=1)
    kf.x = np.zeros((3, 1))
    kf.F = np.array(zoh.F)
    kf.B = np.array(zoh.g).reshape(3, 1)
    kf.H = np.array([[1.0, 0.0, 0.0]])
    kf.P = np.diag([1.0, p.a1, 1.0])
    kf.Q = np.diag([1e-12, 1e-6, 1e-6])
    kf.R = np.array([[1e-4]])
    return kf


def loop_kf(kf, us, zs):
    predict, update = kf.predict, kf.update
    for uk, zk in zip(us, zs, strict=True):
        predict(u=uk)
        update(zk)


def loop_obs(obs, us, zs):
    predict, update = obs.predict, obs.update
    for uk, zk in zip(us, zs, strict=True):
        predict(uk)
        update(zk)


def loop_twin(state, us, zs):
    p, zoh, K = state["params"], state["zoh"], state["K"]
    x, up = np.zeros(3), state["u_prev"]
    for uk, zk in zip(us, zs, strict=True):
        _, x = phso_step(p, zoh, K, x, up, uk, zk)
        up = uk


def timed(fn, *args) -> float:
    gc.collect()
    gc.disable()
    try:
        t0 = time.perf_counter()
        fn(*args)
        return time.perf_counter() - t0
    finally:
        gc.enable()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=9, help="interleaved repetitions (median)")
    ap.add_argument("--steps", type=int, default=2000, help="steps per repetition")
    ap.add_argument("--ukf-steps", type=int, default=300, help="UKF steps per repetition")
    ap.add_argument("--batch-steps", type=int, default=100_000, help="steps for batch_filter")
    ap.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    args = ap.parse_args(argv)

    p = preset("paper_experiment")
    us, zs = record(max(args.steps, args.batch_steps))
    u_list = us.tolist()
    u_step, z_step = u_list[: args.steps], zs[: args.steps]
    u_ukf, z_ukf = u_list[: args.ukf_steps], zs[: args.ukf_steps]
    phso0 = HysteresisObserver(p, GAINS, DT, u_prev=u_list[0])

    # each entry: label -> (make a fresh filter, loop, steps)
    subjects = {
        "PHSO (HysteresisObserver)": (
            lambda: HysteresisObserver(p, GAINS, DT, u_prev=u_list[0]), loop_obs, "step"
        ),
        "ESO (ExtendedStateObserver)": (
            lambda: ExtendedStateObserver(p, GAINS, DT, u_prev=u_list[0]), loop_obs, "step"
        ),
        "filterpy KalmanFilter (dim_x=3, B)": (make_kf, loop_kf, "step"),
        "phso_step (array twin)": (
            lambda: {"params": p, "zoh": discretize(p, DT), "K": phso0.K, "u_prev": u_list[0]},
            loop_twin,
            "step",
        ),
        "UKF (UnscentedObserver)": (
            lambda: UnscentedObserver(p, DT, udot_max=400.0, u_prev=u_list[0]), loop_obs, "ukf"
        ),
    }  # fmt: skip
    data = {"step": (u_step, z_step), "ukf": (u_ukf, z_ukf)}
    per_step: dict[str, list[float]] = {k: [] for k in subjects}
    names = list(subjects)
    print(f"# warm-up and {args.reps} interleaved repetitions", file=sys.stderr)
    for k in names:  # warm-up
        make, loop, which = subjects[k]
        loop(make(), *(x[:50] for x in data[which]))
    for rep in range(args.reps):
        order = names[rep % len(names) :] + names[: rep % len(names)]
        for k in order:
            make, loop, which = subjects[k]
            uu, zz = data[which]
            per_step[k].append(timed(loop, make(), uu, zz) / len(uu))
        print(f"  repetition {rep + 1}/{args.reps}", file=sys.stderr)

    # batch throughput
    batch: dict[str, float] = {}
    for label, make, n in (
        ("PHSO batch_filter", lambda: HysteresisObserver(p, GAINS, DT, u_prev=u_list[0]), None),
        ("ESO batch_filter", lambda: ExtendedStateObserver(p, GAINS, DT, u_prev=u_list[0]), None),
        (
            "UKF batch_filter",
            lambda: UnscentedObserver(p, DT, udot_max=400.0, u_prev=u_list[0]),
            args.ukf_steps * 3,
        ),
    ):
        n = n or args.batch_steps
        runs = [timed(make().batch_filter, zs[:n], us[:n]) for _ in range(3)]
        batch[label] = n / statistics.median(runs)

    kf_med = statistics.median(per_step["filterpy KalmanFilter (dim_x=3, B)"])
    rows = []
    print()
    print(f"Observer step cost, paper_experiment, dt = {DT * 1e3:g} ms, gains {GAINS}")
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    print()
    print(f"| {'predict + update':36s} | median us/step | {'min..max us':>15s} | vs KalmanFilter |")
    print(f"|{'-' * 38}|---------------:|{'-' * 16}:|----------------:|")
    for k in names:
        v = per_step[k]
        med = statistics.median(v)
        rows.append({"name": k, "median_us": med * 1e6, "min_us": min(v) * 1e6,
                     "max_us": max(v) * 1e6, "ratio_to_kf": med / kf_med})  # fmt: skip
        spread = f"{min(v) * 1e6:.2f}..{max(v) * 1e6:.2f}"
        print(f"| {k:36s} | {med * 1e6:14.2f} | {spread:>15s} | {med / kf_med:14.2f}x |")
    print()
    print(f"| {'batch_filter':36s} |  steps/s |")
    print(f"|{'-' * 38}|---------:|")
    for k, v in batch.items():
        print(f"| {k:36s} | {v:8.3g} |")
    phso_med = statistics.median(per_step["PHSO (HysteresisObserver)"])
    verdict = "meets" if phso_med <= kf_med else "misses"
    print()
    print(
        f"PHSO step {phso_med * 1e6:.2f} us vs KalmanFilter {kf_med * 1e6:.2f} us: "
        f"{verdict} the target (PHSO no slower than KalmanFilter)"
    )
    if args.json:
        out = {
            "dt": DT,
            "gains": GAINS,
            "reps": args.reps,
            "steps": args.steps,
            "ukf_steps": args.ukf_steps,
            "python": platform.python_version(),
            "numpy": np.__version__,
            "per_step": rows,
            "batch_steps_per_s": batch,
            "target_met": phso_med <= kf_med,
        }
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)
    return 0 if phso_med <= kf_med else 1


if __name__ == "__main__":
    raise SystemExit(main())
