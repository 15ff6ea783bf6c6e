"""`bwdesign init`, `bwdesign presets` and stage configs by preset name.

The starter file covers every section and key the package reads (checked
against the readers' own tables), loads back to the preset it was written from,
states defaults that are the real defaults, and is never written over a file.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import replace
from pathlib import Path

import pytest

from bwdesign import ConfigError, load_config, load_plant, stage_presets
from bwdesign.cli import init as init_cmd
from bwdesign.cli.main import main
from bwdesign.model import config as config_mod
from bwdesign.model import references
from bwdesign.model.params import MODEL_FIELDS, PHYSICAL_FIELDS
from bwdesign.model.params import PRESETS as PLANT_PRESETS
from bwdesign.model.stage_presets import STAGES_DIR, preset_catalogue, resolve_config
from bwdesign.study import DEFAULT_DECAY

ROOT = Path(__file__).resolve().parents[1]
PRESETS = sorted(stage_presets())


def _bare(cfg):
    """A config without its file identity (source path and hash)."""
    return replace(cfg, source="", sha256="")


def _write(tmp_path: Path, text: str, name: str = "stage.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _uncomment_all(text: str) -> str:
    """Turn every commented section header and ``# key = value`` line into a live one."""
    return re.sub(r"^# (\[\w+\]$|\w+ = )", r"\1", text, flags=re.MULTILINE)


# -- the presets are package data, with one copy ------------------------------


def test_configs_is_a_symlink_to_the_package_data():
    configs = ROOT / "configs"
    assert configs.is_symlink(), "configs/ must stay a link to bwdesign/model/stages/"
    assert configs.resolve() == STAGES_DIR.resolve()
    assert PRESETS == sorted(p.stem for p in configs.glob("*.toml"))
    assert {"paper_experiment", "stack_actuator_800hz"} <= set(PRESETS)


def test_presets_have_one_line_descriptions():
    for name, text in stage_presets().items():
        assert text and "\n" not in text and text.endswith("."), (name, text)


def test_config_accepts_a_preset_name():
    by_name = load_config("paper_experiment")
    by_path = load_config(ROOT / "configs" / "paper_experiment.toml")
    assert by_name == replace(by_path, source=str(STAGES_DIR / "paper_experiment.toml"))
    assert by_name.sha256 == by_path.sha256
    assert load_plant("stack_actuator_800hz") == load_config("stack_actuator_800hz").plant


def test_a_path_that_exists_wins_over_a_preset(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("paper_experiment").write_text((STAGES_DIR / "stack_actuator_800hz.toml").read_text())
    assert resolve_config("paper_experiment") == Path("paper_experiment")
    assert load_config("paper_experiment").plant.name == "stack_actuator_800hz"


@pytest.mark.parametrize(
    "arg, match",
    [
        ("no_such_stage", r"neither a config file nor a stage preset; presets are paper_exp"),
        ("no_such_stage.toml", "does not exist"),
        ("folder/paper_experiment", "does not exist"),
    ],
)
def test_unknown_config_names(arg, match, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match=match):
        load_config(arg)


def test_report_with_an_unknown_preset_is_one_error_line(tmp_path, capsys):
    out = tmp_path / "r"
    code = main(["report", "--config", "no_such_stage", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert err.count("\n") == 1 and err.startswith("error: ") and "stack_actuator_800hz" in err


def test_presets_command(capsys):
    """One list: the stage files and the parameter-only presets, each with where it is taken."""
    names = sorted(set(PRESETS) | set(PLANT_PRESETS))
    assert [e.name for e in preset_catalogue()] == names
    assert main(["presets"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == names
    assert "--plant only; unbounded: refused unless --allow-unbounded" in lines[1]
    assert main(["presets", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    stages = {p["name"]: p["description"] for p in doc["presets"] if p["stage_file"]}
    assert stages == stage_presets()
    assert [p["name"] for p in doc["presets"] if not p["bounded"]] == ["paper_simulation"]


def test_an_unknown_plant_lists_every_preset(capsys):
    assert main(["params", "--plant", "no_such_stage"]) == 2
    err = capsys.readouterr().err
    names = ", ".join(e.name for e in preset_catalogue())
    assert err.count("\n") == 1 and f"presets are {names} (bwdesign presets" in err
    assert "stack_actuator_800hz" in err and "paper_simulation," in err


def test_the_docs_presets_table_is_the_catalogue():
    """The stage-files page's table names every preset the command line takes, and no other."""
    text = (ROOT / "docs/guide/stage-files.md").read_text()
    table = text[text.index("\n## Presets\n") :].split("\n\n")[2]
    rows = [ln.split("|")[1].strip().strip("`") for ln in table.splitlines()[2:]]
    assert rows == [e.name for e in preset_catalogue()]
    row = next(ln for ln in table.splitlines() if ln.startswith("| `paper_simulation` "))
    assert "`params` prints it" in row and "unless `--allow-unbounded`" in row


# -- the starter file ---------------------------------------------------------


def _spec_keys(section: str) -> set[str]:
    if section == "plant":
        groups = (
            init_cmd._PLANT_META,
            init_cmd._PLANT_MODEL,
            init_cmd._PLANT_PHYSICAL,
            init_cmd._PLANT_SHAPE,
        )
        return {k for group in groups for k, _, _ in group}
    return {k for k, _, _ in init_cmd._SPEC[section]}


def test_starter_covers_every_section_and_key_the_package_reads():
    assert set(init_cmd._SECTION_ORDER) == set(config_mod._SECTIONS)
    for section, keys in config_mod._SECTIONS.items():
        if keys is not None:
            assert _spec_keys(section) == keys, section
    assert _spec_keys("plant") == {*MODEL_FIELDS, *PHYSICAL_FIELDS, "name"} | {
        "length_unit",
        "input_unit",
    }
    assert init_cmd._REFERENCE_KEYS == references._KEYS
    assert _spec_keys("reference") == set().union(*references._KEYS.values()) | {"kind"}
    text = init_cmd.starter_config()
    for section in config_mod._SECTIONS:
        assert f"[{section}]" in text
        for key in _spec_keys(section):
            assert re.search(rf"^#?\s*{key}( =|:)", text, re.MULTILINE), (section, key)


@pytest.mark.parametrize("name", PRESETS)
def test_starter_from_a_preset_loads_back_to_the_preset(name, tmp_path):
    text = init_cmd.starter_config(name)
    assert _bare(load_config(_write(tmp_path, text))) == _bare(load_config(name))
    # the commented defaults are the real ones: uncommenting them changes nothing
    live = load_config(_write(tmp_path, _uncomment_all(text), "live.toml"))
    expected = load_config(name)
    expected = replace(expected, synthesis=expected.synthesis or {"decay": DEFAULT_DECAY})
    assert _bare(live) == _bare(expected)


def test_default_starter_is_the_paper_stage_with_its_requirements(tmp_path):
    """[observer] is active beside [requirements], so the starter passes its own check."""
    text = init_cmd.starter_config()
    cfg = load_config(_write(tmp_path, text))
    paper = load_config("paper_experiment")
    assert _bare(cfg) == _bare(paper)
    assert re.search(r"^\[observer\]$", text, re.MULTILINE)
    assert re.search(r"^\[requirements\]$", text, re.MULTILINE)
    assert re.search(r"^# \[synthesis\]$", text, re.MULTILINE)  # the preset has none
    live = load_config(_write(tmp_path, _uncomment_all(text), "live.toml"))
    assert _bare(live) == _bare(replace(paper, synthesis={"decay": DEFAULT_DECAY}))


def test_the_starter_passes_its_own_check(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["init", "stage.toml"]) == 0
    capsys.readouterr()
    assert main(["check", "stage.toml", "--junit-xml", "r.xml"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 6 and all(line.startswith("PASS  stage.toml  ") for line in lines)
    assert Path("r.xml").is_file()


def test_check_writes_no_junit_on_exit_2(tmp_path, capsys, monkeypatch):
    """A starter whose [observer] was removed: exit 2, one error line, no JUnit file."""
    monkeypatch.chdir(tmp_path)
    text = init_cmd.starter_config()
    Path("stage.toml").write_text(text.replace("\n[observer]\n", "\n# [observer]\n# "))
    assert main(["check", "stage.toml", "--junit-xml", "r.xml"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "needs [observer] gains" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stage.toml"]


def test_units_and_defaults_are_stated():
    text = init_cmd.starter_config("paper_experiment")
    assert re.search(r"^dt = 0\.0002 +# s:", text, re.MULTILINE)
    assert re.search(r"^a1 = 159827\.5 +# 1/s\^2:", text, re.MULTILINE)
    assert re.search(r"^margin = 1\.1 +# 1: .*\(default 1\.0\)", text, re.MULTILINE)
    assert re.search(r"^# phase = 0\.0 +# rad: .*\(default 0\.0\)", text, re.MULTILINE)
    assert "pole_radius: rad/s" in text and "= 3997.84 here" in text


# -- the command --------------------------------------------------------------


def test_init_writes_once_and_never_overwrites(tmp_path, capsys):
    path = tmp_path / "stage.toml"
    assert main(["init", str(path)]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {path}; next: bwdesign report")
    first, rest = path.read_text().split("\n", 1)
    assert first.startswith("# written by bwdesign") and "(init)" in first
    assert rest == init_cmd.starter_config()
    path.write_text("# mine\n")
    assert main(["init", str(path), "--preset", "stack_actuator_800hz"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "already exists" in err
    assert path.read_text() == "# mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stage.toml"]


@pytest.mark.parametrize(
    "argv, match",
    [
        (["--preset", "no_such_stage"], "unknown stage preset 'no_such_stage'; presets are"),
        (["--preset", "../stages/paper_experiment"], "unknown stage preset"),
    ],
)
def test_init_bad_preset_writes_nothing(argv, match, tmp_path, capsys):
    path = tmp_path / "stage.toml"
    assert main(["init", str(path), *argv]) == 2
    assert re.search(match, capsys.readouterr().err)
    assert not list(tmp_path.iterdir())


def test_init_into_a_missing_folder(tmp_path, capsys):
    assert main(["init", str(tmp_path / "no" / "stage.toml")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_the_new_file_follows_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        assert main(["init", str(tmp_path / "stage.toml")]) == 0
    finally:
        os.umask(old)
    assert (tmp_path / "stage.toml").stat().st_mode & 0o777 == 0o640


def test_create_new_refuses_an_existing_target_even_after_the_check(tmp_path):
    """The link is the guard: a file that appears after the exists-check is kept."""
    from bwdesign.errors import OutputError
    from bwdesign.output.files import prepare_file

    path = tmp_path / "stage.toml"
    target = prepare_file(path, command="init", exclusive=True)
    path.write_text("theirs\n")
    with pytest.raises(OutputError, match="appeared while bwdesign worked"):
        target.write_text("ours\n")
    assert path.read_text() == "theirs\n"
    assert [p.name for p in tmp_path.iterdir()] == ["stage.toml"]
