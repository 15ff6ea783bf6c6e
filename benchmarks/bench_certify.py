"""Time one certificate per tier (and one synthesis) on the paper's stages.

Run with ``.venv/bin/python benchmarks/bench_certify.py``. A certificate is the
whole tier verdict: the check at ``udot_max``, the bisection of ``max_udot``
to 1 % and of ``decay_rate`` to 1 %, each LMI re-checked outside the solver.
"cold" is the first call in the process (cvxpy compiles the parametrised
program once per thread); "warm" is the median of the following calls.
"""

from __future__ import annotations

import statistics
import sys
import time

from bwdesign import certify, preset, synthesize
from bwdesign.certify.lmi import solver_versions
from bwdesign.certify.results import TIERS

CASES = [
    ("paper_experiment", (8.0, 64.0, -512.0), 360.9, 2e-4),
    ("paper_simulation_corrected", (40.0, 40.0, -80.0), 18.2, 2e-5),
    ("paper_simulation_corrected", (80.0, 160.0, -640.0), 364.2, 2e-5),
]
REPEATS = 7


def _time(fn, *args, **kwargs) -> float:
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
