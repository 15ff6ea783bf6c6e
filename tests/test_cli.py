"""Command-line contract: exit codes and the one-line ``error:`` convention."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bwdesign.cli.main import main

CONFIGS = Path(__file__).resolve().parents[1] / "configs"

GOOD_PLANT = """[plant]
name = "t"
a1 = 159827.5
a2 = 713.8
a3 = 222665.02
alpha = 0.4795
beta = 0.3762
gamma = 0.0378
"""


def run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_params_text_and_json(capsys):
    code, out, err = run(["params", "--plant", str(CONFIGS / "paper_experiment.toml")], capsys)
    assert code == 0 and err == ""
    assert "bounded class: yes" in out and "63.6277 Hz" in out
    code, out, _ = run(["params", "--plant", "paper_simulation", "--json"], capsys)
    doc = json.loads(out)
    assert code == 0
    assert doc["bounded_class"]["bounded"] is False
    assert doc["bounded_class"]["h_max"] is None  # strict JSON, no Infinity
    assert doc["plant"]["beta"] == -1.3567


def test_params_physical(tmp_path, capsys):
    f = tmp_path / "phys.toml"
    f.write_text(
        '[plant]\nname = "p"\nm = 2.0\nb = 10.0\nk = 4e5\nd = 1.5\nalpha0 = 0.3\n'
        "beta = 0.2\ngamma = 0.1\n"
    )
    code, out, _ = run(["params", "--plant", str(f)], capsys)
    assert code == 0 and "physical quantities" in out and "alpha0" in out


BAD = [
    ("unknown preset", None, "unknown plant preset 'no_such_stage'"),
    ("missing file", None, "does not exist"),
    ("malformed TOML", "[plant\na1 = 1\n", "malformed TOML"),
    ("missing [plant]", "[observer]\ngains = [1, 2, 3]\n", "missing required section"),
    ("missing field", GOOD_PLANT.replace("a2 = 713.8\n", ""), "missing field(s) a2"),
    ("non-numeric field", GOOD_PLANT.replace("a2 = 713.8", 'a2 = "fast"'), "a2 must be a number"),
    ("non-finite value", GOOD_PLANT.replace("a1 = 159827.5", "a1 = inf"), "a1 must be finite"),
    ("nan value", GOOD_PLANT.replace("beta = 0.3762", "beta = nan"), "beta must be finite"),
    ("out of range", GOOD_PLANT.replace("alpha = 0.4795", "alpha = -1.0"), "alpha must be > 0"),
    ("unknown key", GOOD_PLANT + "mass = 3\n", "unknown key(s) mass; allowed keys are"),
    ("unknown section", GOOD_PLANT + "[plotting]\ncolor = 1\n", "unknown section(s) [plotting]"),
    ("mixed forms", GOOD_PLANT + "m = 1.0\n", "not both"),
    ("bad gains", GOOD_PLANT + "[observer]\ngains = [1, 2]\n", "list of 3 numbers"),
    (
        "bad envelope",
        GOOD_PLANT + "[envelope]\nudot_max = -3\n",
        "udot_max (input unit/s) = -3 is outside the supported range (0, 1e+09] V/s",
    ),
    ("bad dt", GOOD_PLANT + "[sampling]\ndt = 0\n", "[sampling] dt = 0 is outside"),
    (
        "envelope without reference",
        GOOD_PLANT + "[envelope]\nfrom_reference = true\n",
        "needs a [reference] section",
    ),
]


@pytest.mark.parametrize("label, content, message", BAD, ids=[b[0] for b in BAD])
def test_bad_input_table(tmp_path, capsys, label, content, message):
    if label == "unknown preset":
        plant = "no_such_stage"
    elif content is None:
        plant = str(tmp_path / "absent.toml")
    else:
        plant = str(tmp_path / "stage.toml")
        (tmp_path / "stage.toml").write_text(content)
    code, out, err = run(["params", "--plant", plant], capsys)
    assert code == 2
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ")
    assert message in lines[0]


@pytest.mark.parametrize("argv", [[], ["frobnicate"], ["params"], ["params", "--plant"]])
def test_usage_errors(capsys, argv):
    code, out, err = run(argv, capsys)
    assert code == 2 and out == ""
    assert err.startswith("error: ") and len(err.splitlines()) == 1


def test_module_entry_point_no_traceback():
    r = subprocess.run(
        [sys.executable, "-m", "bwdesign", "params", "--plant", "nope"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert r.stderr.startswith("error: ") and "Traceback" not in r.stderr
