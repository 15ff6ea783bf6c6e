"""Time identification beside one model simulation of the same record (``make bench``).

Two records, each fitted by the default ``identify`` (derived start, 3 starts,
intervals, no ``init``) and printed with its target, the time measured, one
``bwdesign.simulate_zoh`` of the same input (the package's reference plant) and
their ratio:

- a 10 000-sample paper_experiment record at 5 kHz (default multisine
  excitation, 10 nm noise, 3 um offset): target <= 1 s;
- a 50 000-sample 1 Hz sine at 5 kHz, far below the 64 Hz resonance, started
  mid-cycle, with a 7 um offset, a 50 nm sensor drift and 16-bit quantisation:
  target <= 5 s.

And the structural form (issue 30) on the hysteretic benchmark's 8192-sample training
record: one period simulated by the compiled nu = 1 integrator beside the same period by
its Python reference (the ratio is what numba earns there: the same floats, checked
here), and ``identify --form structural --periodic`` on the record (no target; 12 s
before the compiled integrator).

BLAS threads: one, as ``bwdesign identify`` runs (``bwdesign.cli.one_blas_thread``), unless
the caller set them; the settings in force are printed. On shared cores OpenBLAS's thread
pool slows the small SVDs of the fit (measured here, first record: 2.48 s with the pool, 1.59 s
on one thread).
"""

from __future__ import annotations

import os
import statistics
import sys
import time

from bwdesign.cli import one_blas_thread  # loads no numpy

one_blas_thread()  # before numpy loads, as the command line does

import numpy as np  # noqa: E402

from bwdesign import identify, preset, simulate_zoh  # noqa: E402
from bwdesign.identify import IdentificationData  # noqa: E402
from bwdesign.identify.excite import design_excitation, simulate_record  # noqa: E402

DT = 2e-4


def _slow_sine(plant, n: int) -> IdentificationData:
    n_pre = int(1.3 / DT)
    t = np.arange(n_pre + n) * DT
    u = 60.0 + 50.0 * np.sin(2 * np.pi * t + 0.4)
    x = simulate_zoh(plant, u, DT, np.zeros(3), u_prev=u[0])[1 + n_pre :, 0]
    rng = np.random.default_rng(3)
    y = x + 7.0 + 0.05 * t[:n] / t[n - 1] + 0.01 * rng.standard_normal(n)
    q = 1.2 * float(np.ptp(y)) / 2**16
    return IdentificationData.from_arrays(t[:n], u[n_pre:], np.round(y / q) * q, source="sine")


def _line(label: str, rec: IdentificationData, plant, target: float) -> bool:
    sims = []
    for _ in range(5):
        t0 = time.perf_counter()
        simulate_zoh(plant, rec.u, rec.dt, np.zeros(3), u_prev=rec.u[0])
        sims.append(time.perf_counter() - t0)
    sim = statistics.median(sims)
    t0 = time.perf_counter()
    res = identify(rec)
    t_fit = time.perf_counter() - t0
    met = t_fit <= target
    print(
        f"  {label:34s} target <= {target:g} s  measured {t_fit:6.2f} s  one simulate_zoh "
        f"{sim * 1e3:7.2f} ms  ratio {t_fit / sim:6.0f}  {'met' if met else 'NOT met'}; "
        f"fit {res.fit_percent['train']:.3f} %, converged {res.converged}, "
        f"{res.nfev} residual evaluations"
    )
    return met


def main() -> int:
    plant = preset("paper_experiment")
    _, u = design_excitation(plant, umin=0, umax=120, udot_max=2000, duration=10_000 * DT, dt=DT)
    rec = simulate_record(plant, u, DT, noise=0.01, offset=3.0, seed=1)
    threads = {k: os.environ.get(k, "unset") for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    print("bwdesign identification timing (paper_experiment, dt = 2e-4 s)")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}; {threads}")
    ok = _line("10 000-sample multisine", rec, plant, 1.0)
    ok &= _line("50 000-sample 1 Hz sine (mid-cycle)", _slow_sine(plant, 50_000), plant, 5.0)
    ok &= _structural()
    return 0 if ok else 1


def _structural() -> bool:
    """The compiled structural integrator beside its Python reference, and an identification."""
    from bwdesign.identify.hysteretic_benchmark import benchmark_records
    from bwdesign.identify.structural import identify_structural
    from bwdesign.model import structural_sim as S
    from bwdesign.model.structural import BENCHMARK

    rec = benchmark_records(seed=0)["train"]
    fine = S._fine(rec.u, 8, True)
    total = S._steps(rec.u, 8, True)
    args = (BENCHMARK, fine, rec.dt / 8, 8, total, (0.0, 0.0, 0.0))
    S.rk4_compiled(*args)  # compiled (or read from numba's cache) once
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        fast = S.rk4_compiled(*args)
        runs.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    slow = S._rk4_nu1(BENCHMARK, fine.tolist(), *args[2:])
    t_py = time.perf_counter() - t0
    same = all(np.array_equal(a, b) for a, b in zip(fast, slow, strict=True))
    t_c = statistics.median(runs)
    print(
        f"structural nu = 1 period (8192 samples, 8 steps each): compiled {t_c * 1e3:.1f} ms, "
        f"Python reference {t_py * 1e3:.0f} ms, ratio {t_py / t_c:.0f}x, same floats: {same}"
    )
    t0 = time.perf_counter()
    identify_structural([rec], periodic=True)
    print(f"identify --form structural --periodic on that record: {time.perf_counter() - t0:.2f} s")
    return same


if __name__ == "__main__":
    raise SystemExit(main())
