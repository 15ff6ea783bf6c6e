"""Time one certificate per tier (and one synthesis) on the paper's stages.

Run with ``.venv/bin/python benchmarks/bench_certify.py``. A certificate is the
whole tier verdict: the exact envelope and decay rate from the frequency-domain
condition, and a Lyapunov matrix (Riccati or LMI) re-checked outside the solver.
"cold" is the first call in the process (cvxpy compiles the parametrised
program once per thread); "warm" is the median of the following calls.

The last block times full ``certify`` calls (all tiers, with ``dt``) and
``synthesize`` calls over a seeded random set drawn like the audit's
(analysis/certify_audit.py) and prints the quantiles next to the targets
(certify p95 <= 1 s, synthesis <= 2 s) as ratios: wall-clock and CPU time.
"""

from __future__ import annotations

import importlib.util
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from bwdesign import certify, preset, synthesize
from bwdesign.certify.lmi import solver_versions
from bwdesign.certify.results import TIERS
from bwdesign.memo import clear_all

CASES = [
    ("paper_experiment", (8.0, 64.0, -512.0), 360.9, 2e-4),
    ("paper_simulation_corrected", (40.0, 40.0, -80.0), 18.2, 2e-5),
    ("paper_simulation_corrected", (80.0, 160.0, -640.0), 364.2, 2e-5),
]
REPEATS = 7


def _time(fn, *args, **kwargs) -> float:
    """One call's wall time, computed (nothing kept from an earlier call: bwdesign.memo)."""
    clear_all()
    t0 = time.perf_counter()
    fn(*args, **kwargs)
    return time.perf_counter() - t0


def main() -> int:
    print("bwdesign certificate timing (s per call)")
    print(
        f"python {sys.version.split()[0]}; "
        + ", ".join(f"{k} {v}" for k, v in solver_versions().items())
    )
    print()
    head = (
        f"{'plant':<27} {'gains':<17} {'tier':<10} {'cold':>7} {'warm':>7} {'holds':>6} "
        f"{'max |u_dot| V/s':>16}"
    )
    print(head)
    print("-" * len(head))
    worst = 0.0
    for name, gains, v, dt in CASES:
        params = preset(name)
        for tier in TIERS:
            kw = {"udot_max": v, "dt": dt, "tiers": (tier,)}
            cold = _time(certify, params, gains, **kw)
            warm = statistics.median(_time(certify, params, gains, **kw) for _ in range(REPEATS))
            cert = certify(params, gains, **kw).certificates[0]
            worst = max(worst, warm)
            g = ",".join(f"{x:g}" for x in gains)
            print(
                f"{name:<27} {g:<17} {tier:<10} {cold:7.3f} {warm:7.3f} "
                f"{'yes' if cert.holds else 'no':>6} {cert.max_udot:16.4g}"
            )
    print()
    print(f"slowest warm tier certificate: {worst:.3f} s")
    print()
    print(f"{'synthesis':<56} {'warm':>7} {'feasible':>9}")
    params = preset("paper_experiment")
    for kw in ({"udot_max": 400.0, "decay": 50.0}, {"udot_max": 360.0, "decay": 100.0, "dt": 2e-4}):
        synthesize(params, **kw)
        warm = statistics.median(_time(synthesize, params, **kw) for _ in range(3))
        res = synthesize(params, **kw)
        label = "paper_experiment " + ", ".join(f"{k}={v:g}" for k, v in kw.items())
        print(f"{label:<56} {warm:7.3f} {'yes' if res.feasible else 'no':>9}")
    print()
    return 0 if _random_set() else 1


RANDOM_CASES = 40
RANDOM_REQUESTS = 10
CERTIFY_TARGET = 1.0  # s, p95 per call
SYNTHESIS_TARGET = 2.0  # s, per call


def _quantile(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(math.ceil(q * len(xs))) - 1)]


def _random_set() -> bool:
    path = Path(__file__).resolve().parents[1] / "analysis" / "certify_audit.py"
    spec = importlib.util.spec_from_file_location("certify_audit", path)
    audit = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(audit)
    wall, cpu = [], []
    for i in range(RANDOM_CASES):
        rng = np.random.default_rng([7, i])
        p = audit.random_stage(rng)
        lam = audit.random_poles(rng, math.sqrt(p.a1), audit.PATTERNS[i % 5])
        g = audit.gains_from_poles(p, lam)
        v, dt = 10 ** rng.uniform(-3, 7), 10 ** rng.uniform(-6, -3)
        t0, c0 = time.perf_counter(), time.process_time()
        certify(p, g, udot_max=v, dt=dt, allow_unbounded=True)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    swall, scpu = [], []
    for i in range(RANDOM_REQUESTS):
        rng = np.random.default_rng([7, 1000 + i])
        p = audit.random_stage(rng)
        dt = 10 ** rng.uniform(-6, -3) if i % 2 else None
        v = 10 ** rng.uniform(0, 4)
        t0, c0 = time.perf_counter(), time.process_time()
        synthesize(p, udot_max=v, dt=dt, allow_unbounded=True)
        swall.append(time.perf_counter() - t0)
        scpu.append(time.process_time() - c0)
    print(f"random set (seeded): {RANDOM_CASES} certify calls, {RANDOM_REQUESTS} synthesis calls")
    print(f"{'':<22} {'median':>8} {'p95':>8} {'max':>8} {'p95/target':>11}")
    met = True
    for label, xs, target in (
        ("certify wall (s)", wall, CERTIFY_TARGET),
        ("certify cpu (s)", cpu, CERTIFY_TARGET),
        ("synthesize wall (s)", swall, SYNTHESIS_TARGET),
        ("synthesize cpu (s)", scpu, SYNTHESIS_TARGET),
    ):
        p95 = _quantile(xs, 0.95)
        print(
            f"{label:<22} {statistics.median(xs):8.3f} {p95:8.3f} {max(xs):8.3f} "
            f"{p95 / target:11.2f}"
        )
        met = met and p95 <= target
    return met


if __name__ == "__main__":
    raise SystemExit(main())
