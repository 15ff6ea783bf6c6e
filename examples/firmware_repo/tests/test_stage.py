"""The firmware's stage, guarded by bwdesign's pytest helpers."""

from pathlib import Path

from bwdesign.testing import assert_c_matches_python, assert_certified, assert_tracks

STAGE = Path(__file__).resolve().parents[1] / "stage.toml"


def test_gains_are_certified_by_the_sampled_tier():
    assert_certified(STAGE, tier="sampled", decay=20.0)


def test_tracks_the_reference_with_a_two_percent_stiffness_error():
    # the PHSO absorbs a model error slowly: 1.2 um ME here against 0.13 um nominal
    assert_tracks(STAGE, max_me=2.0, max_maxe=5.0, noise_std=0.02, mismatch={"a1": 0.02})


def test_exported_c_matches_python():
    assert_c_matches_python(STAGE, precision="float32")
