"""Time one identification of 10 000 samples beside one model simulation of the same record.

Run with ``.venv/bin/python benchmarks/bench_identify.py`` (``make bench``).
The fit is the default ``identify`` (derived start, 3 refinements, intervals)
without ``init`` on a simulated paper_experiment record (default multisine
excitation, 10 nm noise, 3 um offset). The simulation is one
``bwdesign.simulate_zoh`` call on the same input (the package's reference
plant) and one call of the fit's own split simulator. Target: fit <= 20 s.

BLAS threads: on a shared, oversubscribed machine multi-threaded BLAS in the
optimiser's small SVDs can slow the fit several times over; the timing is
printed with the thread settings in force (OPENBLAS_NUM_THREADS etc.).
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import numpy as np

from bwdesign import identify, preset, simulate_zoh
from bwdesign.identify.excite import design_excitation, simulate_record
from bwdesign.identify.simulate import simulate_output

N = 10_000
DT = 2e-4


def main() -> int:
    plant = preset("paper_experiment")
    _, u = design_excitation(plant, umin=0, umax=120, udot_max=2000, duration=N * DT, dt=DT)
    rec = simulate_record(plant, u, DT, noise=0.01, offset=3.0, seed=1)
    threads = {k: os.environ.get(k, "unset") for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    print(f"bwdesign identification timing: {N} samples at dt = {DT} s (paper_experiment)")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}; {threads}")
    sims = []
    for _ in range(5):
        t0 = time.perf_counter()
        simulate_zoh(plant, u, DT, np.zeros(3), u_prev=u[0])
        sims.append(time.perf_counter() - t0)
    fast = []
    for _ in range(5):
        t0 = time.perf_counter()
        simulate_output(plant, u, DT, np.zeros(3))
        fast.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    res = identify(rec)
    t_fit = time.perf_counter() - t0
    sim = statistics.median(sims)
    print(f"  one simulate_zoh          {sim * 1e3:9.2f} ms")
    print(f"  one fit simulation        {statistics.median(fast) * 1e3:9.2f} ms")
    print(
        f"  identify (3 starts)       {t_fit:9.2f} s  = {t_fit / sim:,.0f} simulate_zoh calls; "
        f"{res.nfev} residual evaluations; target <= 20 s: {'met' if t_fit <= 20 else 'NOT met'}"
    )
    worst = max(abs(getattr(res.params, n) / getattr(plant, n) - 1) for n in ("a1", "a2", "a3"))
    print(
        f"  fit {res.fit_percent['train']:.3f} %, worst linear-parameter error {100 * worst:.3f} %"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
