"""Time ``bwdesign report`` per bundled stage, computed and from the study cache, beside a
reference run in this process.

Run with ``.venv/bin/python benchmarks/bench_report.py [--stage NAME ...] [--repeats N]``.

For every bundled stage (``configs/*.toml``) the report command runs as its own
process (what a user runs: imports included), with a fresh, empty study cache
(``BWDESIGN_CACHE_DIR`` in a temporary folder), after one untimed start that loads
the libraries once (the "warm" start of issue 28: not the first run after install):

- ``cold``: the first report, which computes the study (and keeps it);
- ``cached``: the same report again, read from the cache (median of ``--repeats``).

Each row gives wall time, CPU time and peak RSS of the process (``wait4``; the reports
run before this process imports anything heavy, since a child's peak counts the process
it was forked from). With two cores the report forks a child for part of its study and
another for half its figures (:mod:`bwdesign.study.background`), and it always runs its
compiled batches in a kernel process (:mod:`bwdesign.sim.kernel_process`): the CPU time
is all processes' together, the RSS the largest of them, and "tree" the largest sum of
their RSS at one time (sampled). Then the target (5 s; 15 s
for a stage with ``[sweep]`` or a determined ``[uncertainty]`` box, whose Monte Carlo
and robust sections the report adds) and the ratios to it. The reference is one
``certify`` call of the paper's gains on ``paper_experiment`` (every tier, with
``dt``) timed in this process (median of 5): the report's time over the reference's
says how the machine's speed and load moved both, so numbers from different days and
machines can be compared.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from bwdesign.cli import one_blas_thread  # loads no numpy

one_blas_thread()  # as the command line does

ROOT = Path(__file__).resolve().parents[1]
BWDESIGN = Path(sys.executable).with_name("bwdesign")
TARGET = 5.0  # s, a stage without [sweep] or a robust section
TARGET_HEAVY = 15.0  # s, with them
RSS_TARGET = 250.0  # MB, the largest process


def _tree_rss(pid: int) -> float:
    """Resident memory (MB) of ``pid`` and its descendants now (0 for a process gone)."""
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        try:
            with open(f"/proc/{p}/status") as f:
                total += next(int(l.split()[1]) for l in f if l.startswith("VmRSS")) / 1024
            for t in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{t}/children") as f:
                    todo += [int(c) for c in f.read().split()]
        except (OSError, StopIteration, ValueError):
            continue
    return total


def _run(args: list[str], env: dict[str, str]) -> tuple[float, float, float, float]:
    """``(wall s, cpu s, peak RSS MB, peak RSS of the process tree MB)`` of one command.

    The peak RSS is the largest of the command's processes (``wait4``: its own and its
    children's); the tree's is the largest sum over the command and its children,
    sampled every 10 ms (pages two processes share after a fork are counted twice).
    """
    tree = [0.0]
    with tempfile.TemporaryFile() as log:
        t0 = time.perf_counter()
        proc = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=log)
        done = threading.Event()

        def sample() -> None:
            while not done.wait(0.01):
                tree[0] = max(tree[0], _tree_rss(proc.pid))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        _, status, usage = os.wait4(proc.pid, 0)  # this child's own rusage
        wall = time.perf_counter() - t0
        done.set()
        sampler.join()
        proc.returncode = os.waitstatus_to_exitcode(status)
        log.seek(0)
        err = log.read().decode(errors="replace")
    if proc.returncode not in (0, 1):  # 1: the report says "no", and is written
        raise SystemExit(f"{' '.join(args)} failed ({proc.returncode}):\n{err}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, tree[0]


def _reference() -> float:
    from bwdesign import certify, preset
    from bwdesign.memo import clear_all

    params = preset("paper_experiment")
    kw = {"udot_max": 360.9, "dt": 2e-4}
    certify(params, (8.0, 64.0, -512.0), **kw)  # cvxpy compiles once per process
    times = []
    for _ in range(5):
        clear_all()  # computed each time, not the kept answer (bwdesign.memo)
        t0 = time.perf_counter()
        certify(params, (8.0, 64.0, -512.0), **kw)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _heavy(config: Path) -> bool:
    from bwdesign import load_config

    c = load_config(config)
    return c.sweep is not None or (c.uncertainty is not None and not c.uncertainty.undetermined())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stage", action="append", help="only this bundled stage (repeatable)")
    ap.add_argument("--repeats", type=int, default=3, help="cached runs per stage (median)")
    opts = ap.parse_args(argv)
    stages = sorted((ROOT / "configs").glob("*.toml"))
    if opts.stage:
        stages = [s for s in stages if s.stem in opts.stage]
    print("bwdesign report: wall / CPU time (s) and peak RSS (MB) per bundled stage")
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPU(s), load {os.getloadavg()}")
    # the reports run first, while this process is small: a child's peak RSS counts the
    # memory of the process it was forked from (Linux keeps the larger across exec)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-report-") as tmp:
        env = dict(os.environ)
        warm = "import bwdesign.report.certified, bwdesign.certify.lmi, control"
        subprocess.run([sys.executable, "-c", warm], check=True, env=env)  # libraries read once
        for config in stages:
            env["BWDESIGN_CACHE_DIR"] = str(Path(tmp) / f"cache-{config.stem}")
            out = Path(tmp) / config.stem
            cmd = [str(BWDESIGN), "report", "--config", str(config), "--out", str(out), "--quiet"]
            cold = _run(cmd, env)
            cached = [_run(cmd, env) for _ in range(opts.repeats)]
            rows.append((config, cold, cached))
    ref = _reference()
    print(f"reference: one certify call (paper_experiment, gains (8, 64, -512), dt): {ref:.3f} s")
    print()
    head = (
        f"{'stage':<28} {'target':>6}  {'cold wall':>9} {'cpu':>6} {'RSS':>5} {'tree':>5}  "
        f"{'cached wall':>11} {'cpu':>5} {'RSS':>5}  {'cold/tgt':>8} {'cached/tgt':>10} "
        f"{'cold/ref':>8} {'cached/ref':>10}"
    )
    print(head)
    print("-" * len(head))
    worst = 0.0
    for config, cold, cached in rows:
        cw = statistics.median(c[0] for c in cached)
        cc = statistics.median(c[1] for c in cached)
        cr = max(c[2] for c in cached)
        target = TARGET_HEAVY if _heavy(config) else TARGET
        worst = max(worst, cw / target)
        print(
            f"{config.stem:<28} {target:6.0f}  {cold[0]:9.2f} {cold[1]:6.2f} {cold[2]:5.0f} "
            f"{cold[3]:5.0f}  "
            f"{cw:11.2f} {cc:5.2f} {cr:5.0f}  {cold[0] / target:8.2f} {cw / target:10.2f} "
            f"{cold[0] / ref:8.0f} {cw / ref:10.0f}"
        )
    print()
    print(f"largest cached/target: {worst:.2f} (targets: {TARGET:g} s; {TARGET_HEAVY:g} s with")
    print("[sweep] or a robust section; peak RSS <= 250 MB)")
    rss = max(max(cold[2], *(c[2] for c in cached)) for _, cold, cached in rows)
    print(
        f"largest peak RSS of one process: {rss:.0f} MB (target {RSS_TARGET:g} MB: "
        f"{rss / RSS_TARGET:.2f}); the"
    )
    print("'tree' column: the largest sum over the report's processes (shared pages counted")
    print("in each: the report, its second process, the kernel process)")
    return 0 if worst <= 1.0 and rss <= RSS_TARGET else 1


if __name__ == "__main__":
    raise SystemExit(main())
