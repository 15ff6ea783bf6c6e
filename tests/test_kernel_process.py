"""The compiled kernels' own process (bwdesign.sim.kernel_process): the same results, numba
kept out of the caller, failures run here.

Run in fresh interpreters: a test runner's own threads make a fork unsafe, and the
kernel process is then (rightly) not started.
"""

from __future__ import annotations

import json
import os

import pytest
from conftest import run_python

#: Noisy batches (Gaussian and bounded noise) of corners of the stack's box and a
#: baseline batch, run through ``simulate_batch``; ``batches()`` returns their metrics.
BATCHES = """
import json, os, sys
import numpy as np
from bwdesign import ClosedLoop, load_config, simulate_batch
from bwdesign.design.tuning import digital_tuning
from bwdesign.sim import kernel_process

c = load_config("configs/stack_actuator_800hz.toml")
loop = ClosedLoop.from_config(c, law=digital_tuning(c.plant, c.dt))
base = ClosedLoop.baseline_from_config(c, "pi")
plants = c.uncertainty.vertices(c.plant)[:9]

def batches():
    out = {}
    for kind in ("gaussian", "bounded"):
        noise = [0.0, 0.004] * 4 + [0.01]
        b = simulate_batch(loop, c.reference, plants, duration=0.02, noise_std=noise,
                           seeds=range(9), noise_kind=kind)
        out[kind] = [b.maxe.tolist(), b.rmse.tolist(), b.input_rate_max.tolist()]
    bb = simulate_batch(base, c.reference, plants, duration=0.02, noise_std=0.004,
                        seeds=range(9))
    out["base"] = bb.maxe.tolist()
    return out
"""


def test_importing_the_kernel_process_module_loads_nothing_heavy():
    got = run_python(
        """
        import json, sys
        from bwdesign.sim import kernel_process
        print(json.dumps(sorted({"numpy", "scipy", "numba", "cvxpy"} & set(sys.modules))))
        """
    )
    assert got == []


def test_batches_there_equal_batches_here_a_child_is_served_and_a_kill_means_here():
    """In one interpreter: the batches in the kernel process (numba never loaded here),
    the same batches from a forked child (served there too), then, the kernel process
    killed, the same batches run here (numba loaded here); all equal to the bit."""
    got = run_python(
        BATCHES
        + """
import signal
from bwdesign.study import background
with kernel_process.running() as started:
    assert started and kernel_process.active()
    there = batches()
    numba_there = "numba" in sys.modules
    with background.start([("child", lambda: (batches(), "numba" in sys.modules))]) as bg:
        ok, (child, child_numba) = bg.result("child")
    assert ok
    os.kill(kernel_process._active.pid, signal.SIGKILL)  # the kernel process dies
    os.waitpid(kernel_process._active.pid, 0)
    after = batches()  # run here instead
    numba_after = "numba" in sys.modules
    with kernel_process.running() as again:  # the kernels are here now: none started
        pass
print(json.dumps({"there": there, "numba_there": numba_there, "child": child,
                  "child_numba": child_numba, "after": after, "numba_after": numba_after,
                  "active": kernel_process.active(), "again": again}))
"""
    )
    assert got["numba_there"] is False and got["child_numba"] is False
    assert got["numba_after"] is True  # after the kill: run here
    assert got["child"] == got["there"] == got["after"]  # json keeps every bit of a float
    assert (
        len(set(got["there"]["gaussian"][0])) > 1
        and got["there"]["bounded"] != got["there"]["gaussian"]
    )
    assert got["active"] is False and got["again"] is False


def test_not_started_beside_other_threads_and_the_batch_runs_here():
    got = run_python(
        BATCHES
        + """
import threading
ev = threading.Event()
th = threading.Thread(target=ev.wait); th.start()
try:
    with kernel_process.running() as started:
        out = batches()
finally:
    ev.set(); th.join()
print(json.dumps({"started": started, "numba": "numba" in sys.modules, "n": len(out["base"])}))
"""
    )
    assert got == {"started": False, "numba": True, "n": 9}


@pytest.mark.slow  # a whole report in a fresh interpreter; the suite's reports run in-process
def test_the_report_command_keeps_numba_out_of_its_own_process(tmp_path):
    """The console script: the report's batches ran in the kernel process (nothing of
    numba in the command's process) and the report is the one computed in-process."""
    code = f"""
import json, sys, os
os.environ["BWDESIGN_CACHE_DIR"] = {str(tmp_path / "cache")!r}
from bwdesign.cli import main
code = main(["report", "--config", "paper_experiment", "--out", {str(tmp_path / "a")!r},
             "--quiet", "--no-cache"])
print(json.dumps({{"code": code, "numba": "numba" in sys.modules}}))
"""
    got = run_python(code)
    assert got == {"code": 0, "numba": False}
    a = json.loads((tmp_path / "a" / "certificate.json").read_text())
    assert a["baselines"] and a["robust"]  # the sections whose runs were batched
    assert os.path.exists(tmp_path / "a" / "report.md")


def test_the_kernel_process_answers_only_this_users_processes():
    """A request is a pickle (it runs code when loaded) and an abstract socket's name is
    public: the kernel process reads the peer's user id (SO_PEERCRED) and answers only
    this user's processes."""
    import socket

    from bwdesign.sim import kernel_process

    a, b = socket.socketpair()
    with a, b:
        assert kernel_process._peer_uid(a) == os.getuid()
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    with udp:
        assert kernel_process._peer_uid(udp) == -1  # no peer: unknown, so never answered
