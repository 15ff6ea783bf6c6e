"""Users' CI: the pytest helpers, [requirements], bwdesign check and the example repository."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from bwdesign.cli.main import main
from bwdesign.testing import (
    assert_certified,
    assert_synthesis_feasible,
    assert_tracks,
)

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "firmware_repo"
STAGE = EXAMPLE / "stage.toml"
#: barely Hurwitz gains: the sampled tier holds only up to 34.0 V/s, the envelope is 397
UNCERTIFIED = "gains = [8.0, 64.0, -745.0]"


def _stage_with(tmp_path: Path, old: str, new: str) -> Path:
    text = STAGE.read_text()
    assert old in text
    p = tmp_path / "stage.toml"
    p.write_text(text.replace(old, new))
    return p


def test_helpers_pass_on_the_example_stage():
    assert assert_certified(STAGE, tier="sampled", decay=20.0)[0].passed
    assert assert_synthesis_feasible(STAGE, udot_max=400.0, decay=100.0)[0].passed
    checks = assert_tracks(STAGE, max_me=1.0, max_maxe=5.0)
    assert [c.name for c in checks] == ["max_me_um", "max_maxe_um"]


def test_helpers_fail_with_a_readable_table(tmp_path):
    bad = _stage_with(tmp_path, "gains = [2286.2, 1208283.0, -6256.75]", UNCERTIFIED)
    with pytest.raises(AssertionError) as info:
        assert_certified(bad)
    msg = str(info.value)
    assert msg.splitlines()[0] == "stage.toml: gains not certified"
    assert re.search(r"FAIL\s+certified\s+any\s+None\s+some tier needed at \|u'\| <= 396\.9", msg)
    assert "sampled up to 34.01 V/s" in msg
    with pytest.raises(AssertionError, match=r"FAIL\s+max_me_um\s+0\.01\s+0\.1327"):
        assert_tracks(STAGE, max_me=0.01)
    with pytest.raises(AssertionError, match="synthesis infeasible"):
        assert_synthesis_feasible(STAGE, udot_max=400.0, decay=1e6)


def test_certified_over_an_uncertainty_box():
    box = {"beta": (0.30, 0.45), "gamma": (0.0, 0.06)}
    checks = assert_certified(STAGE, uncertainty=box)
    assert len(checks) == 1 + 4 and all(c.passed for c in checks)


def test_check_passes_on_the_example_and_writes_junit(tmp_path, capsys):
    """Every requirement passes, one line each, in the [requirements] schema's order."""
    xml = tmp_path / "r.xml"
    assert main(["check", str(STAGE), "--junit-xml", str(xml)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 6 and all(line.startswith("PASS  stage.toml  ") for line in lines)
    # check prints check_requirements' checks as they come: their names, in order
    assert [line.split("  ")[2].split(":")[0] for line in lines] == [
        "certified",
        "min_decay",
        "max_me_um",
        "max_maxe_um",
        "min_gain_margin_db",
        "min_phase_margin_deg",
    ]
    suite = ET.parse(xml).getroot().find("testsuite")
    assert suite.get("tests") == "6" and suite.get("failures") == "0"


def test_check_fails_when_a_gain_is_no_longer_certified(tmp_path, capsys):
    bad = _stage_with(tmp_path, "gains = [2286.2, 1208283.0, -6256.75]", UNCERTIFIED)
    xml = tmp_path / "r.xml"
    assert main(["check", str(bad), "--junit-xml", str(xml)]) == 1
    out = capsys.readouterr().out
    assert re.search(r"^FAIL  stage\.toml  certified: some tier needed", out, re.M)
    suite = ET.parse(xml).getroot().find("testsuite")
    assert int(suite.get("failures")) >= 1


@pytest.mark.parametrize(
    "label, old, new, message",
    [
        (
            "unknown key",
            "max_me_um = 1.0",
            "max_me = 1.0",
            r"unknown key\(s\) max_me; allowed keys are certified, min_decay",
        ),
        ("wrong type", "certified = true", 'certified = "yes"', "certified must be true or false"),
        (
            "negative limit",
            "max_me_um = 1.0",
            "max_me_um = -1.0",
            r"max_me_um = -1 is outside the supported range \[0, inf\)",
        ),
        (
            "missing section",
            "[observer]\ngains = [2286.2, 1208283.0, -6256.75]\n",
            "",
            r"needs \[observer\] gains",
        ),
    ],
)
def test_check_bad_input(tmp_path, capsys, label, old, new, message):
    bad = _stage_with(tmp_path, old, new)
    assert main(["check", str(bad)]) == 2, label
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("error:") and re.search(message, err[-1]), err[-1]


def test_check_without_requirements_is_bad_input(tmp_path, capsys):
    text = STAGE.read_text()
    bare = tmp_path / "bare.toml"
    bare.write_text(text[: text.index("[requirements]")])
    assert main(["check", str(bare)]) == 2
    assert "no [requirements] section" in capsys.readouterr().err


def _pytest(folder: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rf"],
        cwd=folder,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )


@pytest.mark.slow
def test_example_repository_passes_and_fails_readably(tmp_path):
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("the example's C test needs a compiler")
    good = _pytest(EXAMPLE)
    assert good.returncode == 0, good.stdout + good.stderr
    assert re.search(r"\b9 passed\b", good.stdout), good.stdout  # 3 helper tests + 6 items
    copy = tmp_path / "repo"
    shutil.copytree(EXAMPLE, copy)
    text = (copy / "stage.toml").read_text()
    (copy / "stage.toml").write_text(
        text.replace("gains = [2286.2, 1208283.0, -6256.75]", UNCERTIFIED)
    )
    bad = _pytest(copy)
    assert bad.returncode == 1
    # the plugin's item reads as a sentence, the helper's message as a table
    assert "stage.toml: gains are certified: some tier needed at |u'| <= 396.9" in bad.stdout
    assert "FAILED tests/test_stage.py::test_gains_are_certified_by_the_sampled_tier" in bad.stdout


def test_bundled_stages_meet_their_requirements(capsys):
    files = sorted(str(p) for p in (ROOT / "configs").glob("*.toml"))
    assert main(["check", *files]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 14 and all(line.startswith("PASS  ") for line in out)
    assert any("worst of nominal and 64 corners" in line for line in out)


# -- gains that are not Hurwitz are a "no", not bad input (issue 24, item 4) ----------

#: l3 of the wrong sign: A = A0 - l C is not Hurwitz (l3 a1 < 0 is violated)
NOT_HURWITZ = "gains = [2286.2, 1208283.0, 6256.75]"


def test_check_fails_on_gains_that_are_not_hurwitz(tmp_path, capsys):
    bad = _stage_with(tmp_path, "gains = [2286.2, 1208283.0, -6256.75]", NOT_HURWITZ)
    xml = tmp_path / "r.xml"
    assert main(["check", str(bad), "--junit-xml", str(xml)]) == 1
    out, err = capsys.readouterr()
    lines = out.strip().splitlines()
    assert (
        err == "" and len(lines) == 6 and all(ln.startswith("FAIL  stage.toml  ") for ln in lines)
    )
    assert re.search(r"^FAIL  stage\.toml  certified: no certificate: .* not Hurwitz", out, re.M)
    assert "l3 a1 < 0 (l3 must be negative)" in lines[0]
    suite = ET.parse(xml).getroot().find("testsuite")
    assert suite.get("failures") == "6" and suite.get("errors") == "0"


def test_assert_certified_on_gains_that_are_not_hurwitz(tmp_path):
    bad = _stage_with(tmp_path, "gains = [2286.2, 1208283.0, -6256.75]", NOT_HURWITZ)
    with pytest.raises(AssertionError) as info:
        assert_certified(bad)
    msg = str(info.value)
    assert msg.splitlines()[0] == "stage.toml: gains not certified"
    assert re.search(r"FAIL\s+certified\s+any\s+None\s+no certificate: .*not Hurwitz", msg)
    with pytest.raises(AssertionError, match=r"FAIL\s+max_me_um\s+1\s+None\s+not simulated"):
        assert_tracks(bad, max_me=1.0)


def test_plugin_reports_gains_that_are_not_hurwitz_as_failed_items(tmp_path):
    _stage_with(tmp_path, "gains = [2286.2, 1208283.0, -6256.75]", NOT_HURWITZ)
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", PYTHONPATH=str(ROOT))
    res = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rf"]
        + ["--bwdesign-configs", "stage.toml"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert res.returncode == 1, res.stdout + res.stderr
    assert re.search(r"\b6 failed\b", res.stdout) and "error" not in res.stdout.split("\n")[-2]
    assert "Traceback" not in res.stdout and "GainError" not in res.stdout
    assert "stage.toml: gains are certified: no certificate: observer gains" in res.stdout


# -- the PHDO's gains come from the one map (issue 24, item 5) ------------------------


@pytest.mark.skipif(
    shutil.which("cc") is None and shutil.which("gcc") is None, reason="needs a C compiler"
)
@pytest.mark.parametrize("stage", ["paper_experiment", "stack_actuator_800hz"])
def test_c_matches_python_for_the_phdo(stage):
    from bwdesign.testing import assert_c_matches_python

    checks = assert_c_matches_python(stage, observer="phdo", steps=2000)
    assert checks[0].passed and "PHDO C vs Python" in checks[0].text


def test_one_map_from_three_state_gains_to_the_phdo(paper_tuning):
    from bwdesign import export_c, load_config
    from bwdesign.codegen.export import c_sources
    from bwdesign.observers.gains import disturbance_gains_from, gains_for_observer

    g = (8.0, 64.0, -512.0)
    assert gains_for_observer("phdo", g) == disturbance_gains_from(g) == (8.0, 64.0, 0.0, -512.0)
    assert gains_for_observer("phso", g) == gains_for_observer("eso", g) == g
    with pytest.raises(ValueError, match="observer must be one of"):
        gains_for_observer("ukf", g)
    tune = paper_tuning
    assert tune.observer_gains_for("phdo") == gains_for_observer("phdo", tune.gains)
    config = load_config("paper_experiment")
    doc = c_sources(config)[3]
    assert tuple(doc["observers"]["phdo"]["gains"]) == gains_for_observer("phdo", config.gains)
    assert callable(export_c)
