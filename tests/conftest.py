"""Shared fixtures: the canonical stages of the paper."""

import pytest
from hypothesis import settings

from bwdesign import preset

# Property tests draw the same examples on every run (seeded, no flaky CI); the
# example database is not consulted, so a clean checkout behaves like any other.
settings.register_profile("bwdesign", derandomize=True, database=None)
settings.load_profile("bwdesign")


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
