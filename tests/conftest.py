"""Shared fixtures: the canonical stages of the paper, and expensive results computed once.

The tests run OpenBLAS on one thread (:func:`one_blas_thread`): the package's linear
algebra is on small matrices (a loop's few states), where OpenBLAS's threads only cost (on a
2-core machine: a 6x6 ``solve_triangular`` 0.65 ms with the default threads, 11 us with
one; the study of configs/paper_experiment.toml 19.9 s of CPU against 11.0 s), and
pytest-xdist's workers would fight over the cores.

A result many tests read (a written report) is computed once per test run by
:func:`once`, also when pytest-xdist spreads the tests over several worker processes:
the first worker that asks builds it under a file lock, the others wait and read the
files. The files are made read-only and every fixture returns fresh objects (parsed
text, copies), so no test can change what another reads. (``--dist loadgroup`` cannot
keep the readers on one worker: pytest-xdist 3.8 renames the grouped tests through
``item._nodeid``, which pytest 9 no longer reads, so every test is its own group.)
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import textwrap
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import settings

from bwdesign import preset

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: each worker builds its own copy
    fcntl = None


#: OpenBLAS's thread setters: numpy's and scipy's wheels (ILP64 and LP64), a system build
SET_THREADS = (
    "scipy_openblas_set_num_threads64_",
    "scipy_openblas_set_num_threads",
    "openblas_set_num_threads",
)


def one_blas_thread() -> None:
    """OpenBLAS on one thread here and in every process the tests start.

    ``OPENBLAS_NUM_THREADS`` (unless set) reaches the xdist workers and the
    subprocesses; numpy's and scipy's OpenBLAS are already loaded here (the bwdesign
    pytest plugin imports numpy before this file), so each is also told directly.
    """
    import ctypes

    import scipy.linalg  # noqa: F401  (loads scipy's OpenBLAS, so it is found below)

    threads = int(os.environ.setdefault("OPENBLAS_NUM_THREADS", "1"))
    try:
        with open("/proc/self/maps") as maps:
            libs = {line.split()[-1] for line in maps if "openblas" in line.lower()}
    except OSError:  # not Linux: the environment variable reaches new processes only
        return
    for path in sorted(libs):
        lib = ctypes.CDLL(path)
        for name in SET_THREADS:
            if hasattr(lib, name):
                getattr(lib, name)(threads)


one_blas_thread()

# Property tests draw the same examples on every run (seeded, no flaky CI); the
# example database is not consulted, so a clean checkout behaves like any other.
settings.register_profile("bwdesign", derandomize=True, database=None)
settings.load_profile("bwdesign")

ROOT = Path(__file__).resolve().parents[1]
PAPER_CONFIG = ROOT / "configs" / "paper_experiment.toml"
#: the Date line of the reports the tests write (two runs must compare equal)
REPORT_DATE = "2000-01-01 00:00 UTC"

#: The heaviest test modules, heaviest first, by the sum of their tests' durations under
#: ``make test`` (s, rounded); the others follow in file order. Under xdist the modules are
#: given out in this order (``make test``: one module per worker at a time, ``--dist
#: loadfile --no-loadscope-reorder``), so no 20-50 s module runs alone at the end.
#: test_claims_report.py and test_study_cache.py come after test_report.py has had time
#: to write the shared paper_experiment report (:func:`paper_report`) they read.
HEAVY_MODULES = (  # seconds of test time each, measured on 2 cores (durations, 2026-12-08)
    "tests/test_identify_extensions.py",  # 27
    "tests/test_report.py",  # 23: the shared report, a second one, the not-certified one
    "tests/test_background.py",  # 22: studies on two processes
    "tests/test_sweep.py",  # 20: a report with [sweep] and [uncertainty]
    "tests/test_robust_bounds.py",  # 18
    "tests/test_claims_report.py",  # 16: the saturating and the unbounded reports
    "tests/test_robust_observer.py",  # 16
    "tests/test_observers.py",  # 16
    "tests/test_baselines.py",  # 15
    "tests/test_simulate.py",  # 13
    "tests/test_structural.py",  # 12: the benchmark records
    "tests/test_codegen.py",  # 12: the C compiler
    "tests/test_robust.py",  # 11
    "tests/test_kernel_process.py",  # 11: fresh interpreters
    "tests/test_certify.py",  # 11
    "tests/test_docs_site.py",  # 7 when the site is built: Chromium
    "tests/test_study_cache.py",  # 6: reads the shared report's cache
)


_SESSION: dict[str, str | None] = {}


def pytest_configure(config):
    """A study cache for the session, set before test modules load (some build the
    environment of their subprocesses then): no test reads or writes a user's cache."""
    _SESSION["before"] = os.environ.get("BWDESIGN_CACHE_DIR")
    _SESSION["dir"] = tempfile.mkdtemp(prefix="bwdesign-test-cache-")
    os.environ["BWDESIGN_CACHE_DIR"] = _SESSION["dir"]


def pytest_unconfigure(config):
    if "dir" in _SESSION:
        shutil.rmtree(_SESSION["dir"], ignore_errors=True)
        if _SESSION["before"] is None:
            os.environ.pop("BWDESIGN_CACHE_DIR", None)
        else:
            os.environ["BWDESIGN_CACHE_DIR"] = _SESSION["before"]


@pytest.fixture(autouse=True)
def _own_study_cache(tmp_path_factory, monkeypatch):
    """Every test has its own, empty study cache (commands keep studies there): a test
    never reads a study another test or a user's run kept (bwdesign.study.cache)."""
    monkeypatch.setenv("BWDESIGN_CACHE_DIR", str(tmp_path_factory.mktemp("study-cache")))


@pytest.fixture(autouse=True)
def _nothing_kept_across_a_patch(monkeypatch):
    """The package keeps pure functions' answers (bwdesign.memo); a test that replaces
    anything (monkeypatch.setattr, setitem, delattr, delitem) computes afresh: every kept
    answer is forgotten when it patches, so no test's patch is hidden by an answer kept
    before, and when it ends the answers kept before its first patch come back
    (memo.restore), so no answer computed under a patch reaches another test and the
    tests after it do not compute again what was kept. Setting an environment variable
    (monkeypatch.setenv) is not a patch of the package."""
    from bwdesign import memo

    before = []  # the answers kept before the test's first patch
    for name in ("setattr", "setitem", "delattr", "delitem"):
        real = getattr(monkeypatch, name)

        def forgetting(*args, _real=real, **kwargs):
            if not (args and args[0] is os.environ):  # setenv is setitem on os.environ
                if not before:
                    before.append(memo.snapshot())
                memo.clear_all()
            return _real(*args, **kwargs)

        object.__setattr__(monkeypatch, name, forgetting)
    yield
    if before:
        memo.restore(before[0])


@pytest.fixture(params=["paper_experiment", "paper_simulation_corrected"])
def usable_plant(request):
    """Both bounded paper presets."""
    return preset(request.param)


@pytest.fixture
def experiment():
    return preset("paper_experiment")


@pytest.fixture
def simulation():
    return preset("paper_simulation_corrected")


@pytest.fixture(scope="session")
def paper_tuning_session():
    """``digital_tuning(preset("paper_experiment"), 2e-4)``, computed once per process
    (1.3 s); for module fixtures that only read it (tests take :func:`paper_tuning`)."""
    from bwdesign import digital_tuning

    return digital_tuning(preset("paper_experiment"), 2e-4)


@pytest.fixture
def paper_tuning(paper_tuning_session):
    """The paper stage's digital tuning at 0.2 ms (:func:`paper_tuning_session`), a copy
    for each test. For tests that use the tuning; the tests of digital_tuning itself
    (tests/test_loop.py) call it."""
    return copy.deepcopy(paper_tuning_session)


def pytest_collection_modifyitems(config, items):
    """Under xdist, the modules of :data:`HEAVY_MODULES` first (longest first balances)."""
    if not config.pluginmanager.hasplugin("xdist"):
        return  # one process: the order does not change the time
    rank = {name: i for i, name in enumerate(HEAVY_MODULES)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))  # stable


def _shared_root(tmp_path_factory) -> Path:
    """The run's temporary root: the same directory for every xdist worker of one run."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def once(tmp_path_factory, name: str, build: Callable[[Path], None]) -> Path:
    """The directory ``build(path)`` fills, built once per test run, then read-only.

    ``build`` writes into a new directory; a build that raises leaves nothing behind
    (the next caller builds again and sees the same error).
    """
    root = _shared_root(tmp_path_factory)
    target = root / f"shared-{name}"
    with open(root / f"shared-{name}.lock", "w") as lock:
        if fcntl is not None:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not (target / ".built").exists():
            shutil.rmtree(target, ignore_errors=True)
            build(target)
            for p in target.rglob("*"):
                if p.is_file():
                    p.chmod(stat.S_IRUSR | stat.S_IRGRP | stat.S_IROTH)
            (target / ".built").touch()
    return target


@dataclass(frozen=True)
class WrittenReport:
    """A report ``bwdesign report`` wrote: its folder and what it returned.

    ``md`` and ``cert`` read the files on every access (a fresh dict each time).
    """

    out_dir: Path
    certified: bool
    #: the study cache the report was computed into (read-only, like the report)
    cache_dir: Path | None = None

    @property
    def md(self) -> str:
        return (self.out_dir / "report.md").read_text()

    @property
    def cert(self) -> dict:
        return json.loads((self.out_dir / "certificate.json").read_text())


def write_report_once(tmp_path_factory, name: str, config_path: Path) -> WrittenReport:
    """``write_report`` of ``config_path`` (quiet, dated :data:`REPORT_DATE`), once per run,
    into an empty study cache kept beside it (``WrittenReport.cache_dir``: what a report
    computed with a cache keeps, for tests/test_study_cache.py to read back)."""
    from bwdesign.model.config import load_config
    from bwdesign.output.files import ResultCache
    from bwdesign.report.certified import write_report
    from bwdesign.study.cache import StudyCache

    def build(path: Path) -> None:
        path.mkdir(parents=True)
        outcome = write_report(
            load_config(config_path),
            path / "report",
            quiet=True,
            date=REPORT_DATE,
            cache=StudyCache(ResultCache(path / "cache")),
        )
        (path / "certified.json").write_text(json.dumps(outcome.certified))

    path = once(tmp_path_factory, name, build)
    certified = json.loads((path / "certified.json").read_text())
    return WrittenReport(out_dir=path / "report", certified=certified, cache_dir=path / "cache")


@pytest.fixture(scope="session")
def paper_report(tmp_path_factory) -> WrittenReport:
    """The certified-gains report of ``configs/paper_experiment.toml``, written once per run.

    Read by the report's content tests (tests/test_report.py) and the report's claims
    (tests/test_claims_report.py); every one of them only reads it.
    """
    return write_report_once(tmp_path_factory, "paper_report", PAPER_CONFIG)


def run_python(code: str, *, timeout: float = 120) -> dict:
    """Run ``code`` (dedented) in a fresh interpreter at the repository's root: it must
    exit 0; its last line of output, JSON, is returned. For what a test runner's own
    threads forbid in its process (a fork) or what its imports would hide."""
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def headless_chromium(window: str = "1280,2000"):
    """A headless Chromium (selenium) for the browser tests; skipped without one, failed
    under ``BWDESIGN_REQUIRE_BROWSER=1`` (CI installs chromium and chromium-driver)."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    chromedriver = shutil.which("chromedriver")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        chromium = None
    if not (chromium and chromedriver):
        if os.environ.get("BWDESIGN_REQUIRE_BROWSER") == "1":
            pytest.fail("BWDESIGN_REQUIRE_BROWSER=1 but chromium/chromedriver/selenium missing")
        pytest.skip("no headless Chromium (install chromium and chromium-driver)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--window-size={window}",
    ):
        opts.add_argument(flag)
    return webdriver.Chrome(service=Service(chromedriver), options=opts)
