"""The second process (bwdesign.study.background): results sent back, failures computed here.

Run in a fresh interpreter: a test runner's own threads make :func:`available` say no
(a fork copies only the calling thread), as it should.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import run_python

from bwdesign.errors import InputError
from bwdesign.study import background

ROOT = Path(__file__).resolve().parents[1]


def test_background_sends_results_and_gives_up_on_failures():
    got = run_python(
        """
        import json, os
        from bwdesign.study import background
        assert background.available()
        def boom():
            raise ValueError("no")
        bg = background.start(
            [("a", lambda: 2 + 2), ("pid", os.getpid), ("bad", boom), ("after", lambda: 1)]
        )
        with bg:
            out = {k: list(bg.result(k)) for k in ("a", "pid", "bad", "after", "unknown")}
        unpicklable = background.start([("f", lambda: (lambda: 0))])
        with unpicklable:
            out["f"] = unpicklable.result("f")[0]
        out["me"] = os.getpid()
        out["none"] = background.start([]) is None
        print(json.dumps(out))
        """
    )
    assert got["a"] == [True, 4]
    assert got["pid"][0] and got["pid"][1] != got["me"]  # computed in the child
    assert got["bad"] == [False, None]  # the caller computes it (and raises) itself
    assert got["after"] == [False, None]  # the child stops at the first failure
    assert got["unknown"] == [False, None]
    assert got["f"] is False
    assert got["none"]


def test_split_computes_every_second_task_there_and_raises_errors_in_order():
    got = run_python(
        """
        import json, os
        from bwdesign.study import background
        me = os.getpid()
        def where(k):
            return lambda: [k, os.getpid() == me]
        def fail(k):
            def f():
                raise ValueError(k)
            return f
        def only_here(k):
            def f():
                if os.getpid() != me:
                    raise RuntimeError("not in the child")
                return k
            return f
        out = {"values": background.split([(str(k), where(k)) for k in range(5)])}
        # here=False: both halves in children of their own, the same values
        out["away"] = background.split([(str(k), where(k)) for k in range(3)], here=False)
        out["away_fallback"] = background.split(
            [("a", only_here("a")), ("b", where("b"))], here=False
        )
        out["one"] = background.split([("a", where("a"))])
        out["none"] = background.split([])
        # the child's task fails there: computed here, in its turn
        out["fallback"] = background.split([("a", where("a")), ("b", only_here("b"))])
        errors = {}
        for name, tasks in {
            "child_first": [("a", where("a")), ("b", fail("b")), ("c", fail("c"))],
            "here_first": [("a", fail("a")), ("b", fail("b"))],
        }.items():
            try:
                background.split(tasks)
            except ValueError as e:
                errors[name] = str(e)
        out["errors"] = errors
        # a child at work runs no thread here: this process may fork again meanwhile
        import time
        bg = background.start([("x", lambda: (time.sleep(0.5), 7)[1])])
        out["after_start"] = [background.available(), list(bg.result("x"))]
        bg.close()
        print(json.dumps(out))
        """
    )
    # even positions here (True), odd ones in the child (False), in the tasks' order
    assert got["values"] == [[0, True], [1, False], [2, True], [3, False], [4, True]]
    assert got["away"] == [[0, False], [1, False], [2, False]]
    assert got["away_fallback"] == ["a", ["b", False]]  # failed there: computed here
    assert got["one"] == [["a", True]] and got["none"] == []
    assert got["fallback"] == [["a", True], "b"]
    assert got["errors"] == {"child_first": "b", "here_first": "a"}
    assert got["after_start"] == [True, [True, 7]]


def test_background_not_available_with_other_threads():
    # this test process runs pytest's threads (or may): available() must not fork then
    import threading

    ev = threading.Event()
    t = threading.Thread(target=ev.wait)
    t.start()
    try:
        assert not background.available()
        assert background.start([("a", lambda: 1)]) is None
    finally:
        ev.set()
        t.join()


def test_study_with_two_workers_is_the_same_study():
    got = run_python(
        """
        import json, os
        import bwdesign.study.compute as C
        from bwdesign.model.config import load_config
        me, computed = os.getpid(), []
        for part in C.BESIDE:
            f = C._COMPUTE[part]
            C._COMPUTE[part] = lambda r, f=f, part=part: (computed.append(part), f(r))[1]
        cfg = load_config("configs/paper_simulation_corrected.toml")
        from bwdesign.study.result import CERTIFICATE_PARTS
        parts = CERTIFICATE_PARTS | {"tier_synthesis"}
        one = C.study(cfg, parts=parts)
        here = list(computed)
        computed.clear()
        two = C.study(cfg, parts=parts, workers=2)
        same = one.to_dict() == two.to_dict() and one.verdict == two.verdict
        print(json.dumps({"same": same, "one": here, "two": computed, "beside": C.BESIDE}))
        """
    )
    assert got["same"]
    assert sorted(got["one"]) == sorted(got["beside"])  # alone: every part here
    assert "tier_synthesis" in got["beside"]
    assert got["two"] == []  # computed by the second process


def test_workers_checked():
    from bwdesign.model.config import load_config
    from bwdesign.study import study

    cfg = load_config(ROOT / "configs" / "paper_simulation_corrected.toml")
    for bad in (0, 1.5, True, "2"):
        with pytest.raises(InputError, match="workers"):
            study(cfg, parts=("plant",), workers=bad)


def test_the_error_is_the_one_the_order_of_parts_meets_first():
    """With the second process, a failing part raises only after the BESIDE parts that
    come before it in PARTS: the same error as computing the parts in order."""
    got = run_python(
        """
        import json
        import bwdesign.study.compute as C
        from bwdesign.model.config import load_config
        def fail(name):
            def f(r):
                raise ValueError(name)
            return f
        C._COMPUTE["configured"] = fail("configured")
        C._COMPUTE["tuning"] = fail("tuning")
        cfg = load_config("configs/paper_simulation_corrected.toml")
        out = {}
        for w in (1, 2):
            try:
                C.study(cfg, parts=("configured", "tuning"), workers=w)
            except ValueError as e:
                out[w] = str(e)
        print(json.dumps(out))
        """
    )
    assert got == {"1": "configured", "2": "configured"}


def test_the_robust_section_begun_by_children_is_the_same_and_its_error_comes_first():
    """workers=2: the robust loops are certified by two children while this process
    computes the baselines; the study is the one computed alone, and a failing robust
    loop (raised only here) is the error, before a failing later part (the baselines)."""
    got = run_python(
        """
        import json, os
        import bwdesign.study.compute as C
        import bwdesign.study.robust as R
        from bwdesign.model.config import load_config
        from bwdesign.study.result import CERTIFICATE_PARTS
        cfg = load_config("configs/paper_simulation_corrected.toml")
        parts = CERTIFICATE_PARTS | {"robust", "baselines"}
        one = C.study(cfg, parts=parts)
        two = C.study(cfg, parts=parts, workers=2)
        out = {"same": one.to_dict() == two.to_dict()}
        me, loop = os.getpid(), R.robust_loop
        def here_only(*a, **k):
            if os.getpid() != me:
                raise RuntimeError("only here")
            return loop(*a, **k)
        R.robust_loop = here_only  # the children fail: every loop computed here
        out["fallback"] = C.study(cfg, parts=parts, workers=2).to_dict() == one.to_dict()
        def fail(*a, **k):
            raise ValueError("robust")
        def fail_baselines(r):
            raise ValueError("baselines")
        R.robust_loop = fail
        C._COMPUTE["baselines"] = fail_baselines
        for w in (1, 2):
            try:
                C.study(cfg, parts=parts, workers=w)
            except ValueError as e:
                out[str(w)] = str(e)
        print(json.dumps(out))
        """,
        timeout=300,
    )
    assert got == {"same": True, "fallback": True, "1": "robust", "2": "robust"}


def test_figures_drawn_on_two_processes_are_the_same_and_failures_drawn_here(tmp_path):
    got = run_python(
        f"""
        import json, os
        from pathlib import Path
        from matplotlib.figure import Figure
        from bwdesign.report.figures import FigureWriter
        me = os.getpid()
        def fig(k, fail_in_child=False):
            def draw():
                if fail_in_child and os.getpid() != me:
                    raise RuntimeError("only in the child")
                f = Figure(figsize=(2, 2))
                f.subplots().plot([0, 1, 2], [0, k, 2 * k])
                return f
            return draw
        out = {{}}
        for w in (1, 2):
            figs = FigureWriter(Path({str(tmp_path)!r}) / str(w), workers=w)
            for k in range(4):
                figs.save(f"f{{k}}.png", fig(k, fail_in_child=(k == 3)))
            figs.finish()
            out[w] = {{n: p.read_bytes().hex() for n, p in figs.written.items()}}
        print(json.dumps({{"same": out[1] == out[2], "names": sorted(out[2])}}))
        """
    )
    assert got == {"same": True, "names": ["f0.png", "f1.png", "f2.png", "f3.png"]}


def test_a_child_solves_lmis_after_this_process_did():
    """Clarabel runs on one thread (bwdesign.certify.lmi.core): a child forked after this
    process solved an LMI solves too. With its thread pool, a pool the parent had started
    does not survive the fork and the child's solve waited for it forever."""
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            textwrap.dedent(
                """
                import json, os, threading
                import cvxpy as cp, numpy as np
                from importlib import import_module
                from bwdesign.study import background
                core = import_module("bwdesign.certify.lmi.core")

                def solve():
                    X = cp.Variable((24, 24), symmetric=True)
                    C = np.diag(np.arange(1.0, 25.0))
                    p = cp.Problem(cp.Minimize(cp.trace(C @ X)), [X >> np.eye(24)])
                    return float(core.solve(p, {"X": X}).values["X"][0, 0])

                here = solve()
                threads = len(os.listdir(f"/proc/{os.getpid()}/task"))
                with background.start([("x", solve)]) as bg:
                    ok, there = bg.result("x")
                print(json.dumps({"ok": ok, "same": there == here, "threads": threads}))
                """
            ),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got == {"ok": True, "same": True, "threads": got["threads"]}
    assert got["threads"] <= 3  # Clarabel started no threads of its own (before: 5)
