"""Shared fixtures: the canonical stages of the paper."""

import pytest

from bwdesign import preset


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
