"""Shared fixtures: the canonical stages of the paper."""

import os
import shutil
import tempfile

import pytest
from hypothesis import settings

from bwdesign import preset

# Property tests draw the same examples on every run (seeded, no flaky CI); the
# example database is not consulted, so a clean checkout behaves like any other.
settings.register_profile("bwdesign", derandomize=True, database=None)
settings.load_profile("bwdesign")


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
