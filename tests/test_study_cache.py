"""The study cache (issue 28): a kept study reads back as the one computed, and only then.

A report written from the cache is byte for byte the one computed without it; the
key changes with the stage file, the settings, the code and the libraries; a damaged
entry is computed again, never an error; ``--no-cache`` neither reads nor keeps; the
cache is never in an output directory; the store never touches a file it did not write.
"""

from __future__ import annotations

import os
import pickle
import shutil
import stat
from pathlib import Path

import pytest

from bwdesign import load_config
from bwdesign.cli.main import main
from bwdesign.output.files import ResultCache, default_cache_dir
from bwdesign.output.files import cache as store_mod
from bwdesign.output.jsonenc import dump_json
from bwdesign.report.certified import REPORT_FILES, write_report
from bwdesign.study import StudySettings, study
from bwdesign.study import cache as cache_mod
from bwdesign.study.cache import StudyCache

ROOT = Path(__file__).resolve().parents[1]
STAGE = ROOT / "examples" / "firmware_repo" / "stage.toml"
CONFIG = ROOT / "configs" / "paper_experiment.toml"
DATE = "2000-01-01 00:00 UTC"
CHEAP = {"plant", "envelope", "configured"}


def _tree(path: Path) -> dict[str, bytes]:
    """Every file of a report (the manifest aside), its own --out path written as OUT."""
    return {
        p.relative_to(path).as_posix(): p.read_bytes().replace(str(path).encode(), b"OUT")
        for p in sorted(path.rglob("*"))
        if p.is_file() and p.name != ".bwdesign-manifest.json"
    }


def _same(a, b) -> bool:
    """Two results hold the same numbers (their JSON, bit for bit)."""
    return dump_json(a.to_dict()) == dump_json(b.to_dict())


@pytest.fixture
def computed(paper_report, tmp_path):
    """The report of configs/paper_experiment.toml computed into an empty cache
    (conftest's paper_report, computed once per test run): ``(a copy of that cache, the
    report's files)``."""
    shutil.copytree(paper_report.cache_dir, tmp_path / "cache")
    for p in (tmp_path / "cache").rglob("*"):
        p.chmod(p.stat().st_mode | stat.S_IWUSR)
    return StudyCache(ResultCache(tmp_path / "cache")), _tree(paper_report.out_dir)


def test_a_report_from_the_cache_is_the_computed_one_byte_for_byte(
    computed, tmp_path, monkeypatch, capsys
):
    cache, first = computed
    kinds = sorted(p.suffix for p in cache.store.entries())
    assert kinds == [".figures", ".study"]
    import bwdesign.plotting.figures as plotting
    import bwdesign.study.compute as compute

    def no(*a, **k):
        raise AssertionError("a kept study must not be computed or drawn again")

    monkeypatch.setattr(plotting, "save_figure", no)
    monkeypatch.setattr(compute, "synthesize_per_tier", no)
    monkeypatch.setattr(compute, "digital_tuning", no)
    write_report(load_config(CONFIG), tmp_path / "again", date=DATE, cache=cache)
    assert _tree(tmp_path / "again") == first
    assert set(first) >= set(REPORT_FILES) and any(k.startswith("figures/") for k in first)
    assert "[report] study read from the cache" in capsys.readouterr().err
    # computed without a cache, the same report: tests/test_report.py,
    # test_two_runs_are_identical (every file, the figures too)
    monkeypatch.undo()
    # write_report without a cache keeps nothing, and draws the figures again: the same
    # bytes (the study handed to it is the one just read back, so it is not computed a
    # third time)
    import bwdesign.report.certified as certified

    kept = study(load_config(CONFIG), cache=cache)
    assert kept.cached == kept.parts  # read back, nothing computed

    def read_back(config, **kw):
        assert kw["cache"] is None
        return kept

    monkeypatch.setattr(certified, "study", read_back)
    monkeypatch.setenv("BWDESIGN_CACHE_DIR", str(tmp_path / "unused"))
    write_report(load_config(CONFIG), tmp_path / "fresh", quiet=True, date=DATE)
    assert _tree(tmp_path / "fresh") == first
    assert not (tmp_path / "unused").exists()


def test_the_cache_is_never_in_the_output_directory(computed, tmp_path):
    cache, first = computed
    write_report(load_config(CONFIG), tmp_path / "out", quiet=True, date=DATE, cache=cache)
    names = {p.name for p in (tmp_path / "out").rglob("*")}
    assert not any(n.endswith((".study", ".figures")) for n in names)
    assert cache.store.root not in (tmp_path / "out").parents


def test_a_hit_reads_the_parts_and_computes_only_the_missing_ones(tmp_path):
    cache = StudyCache(ResultCache(tmp_path))
    config = load_config(STAGE)
    a = study(config, parts=CHEAP, cache=cache)
    assert a.cached == frozenset() and a.cache_key is not None
    b = study(config, parts=CHEAP, cache=cache)
    assert b.cached == a.parts and _same(b.configured, a.configured) and b.plant == a.plant
    c = study(config, parts=CHEAP | {"synthesis"}, cache=cache)
    assert c.cached == a.parts and "synthesis" in c.parts
    d = study(config, parts={"synthesis"}, cache=cache)  # the union was kept
    assert d.cached >= c.parts and _same(d.synthesis.result, c.synthesis.result)
    # the Python API uses no cache unless given one
    assert study(config, parts=CHEAP).cache_key is None


def test_a_changed_stage_file_or_setting_misses(tmp_path):
    cache = StudyCache(ResultCache(tmp_path / "cache"))
    stage = tmp_path / "stage.toml"
    text = STAGE.read_text()
    stage.write_text(text)
    first = study(load_config(stage), parts=CHEAP, cache=cache)
    stage.write_text(text)  # same bytes, new file time: a hit
    assert study(load_config(stage), parts=CHEAP, cache=cache).cached == first.parts
    stage.write_text(text.replace("gains = [2286.2,", "gains = [2286.3,"))
    changed = study(load_config(stage), parts=CHEAP, cache=cache)
    assert changed.cached == frozenset() and changed.cache_key != first.cache_key
    assert changed.configured.gains != first.configured.gains
    stage.write_text(text + "\n# a comment changes the file, so the key\n")
    assert study(load_config(stage), parts=CHEAP, cache=cache).cached == frozenset()
    other = StudySettings(decay=5.0)
    assert study(load_config(stage), parts=CHEAP, cache=cache, settings=other).cached == set()
    key = cache.key(load_config(stage), False, StudySettings(), {"numpy": "1"})
    assert key != cache.key(load_config(stage), True, StudySettings(), {"numpy": "1"})
    assert key != cache.key(load_config(stage), False, StudySettings(), {"numpy": "2"})


def test_changed_code_misses(tmp_path, monkeypatch):
    cache = StudyCache(ResultCache(tmp_path))
    config = load_config(STAGE)
    first = study(config, parts=CHEAP, cache=cache)
    monkeypatch.setattr(cache_mod, "source_fingerprint", lambda: "edited")
    again = study(config, parts=CHEAP, cache=cache)
    assert again.cached == frozenset() and again.cache_key != first.cache_key


def test_the_fingerprint_covers_the_package_source():
    cache_mod.source_fingerprint.cache_clear()
    fp = cache_mod.source_fingerprint()
    assert len(fp) == 64 and fp == cache_mod.source_fingerprint()


@pytest.mark.parametrize("damage", ["flip", "truncate", "not_a_pickle", "not_parts", "empty"])
def test_a_damaged_entry_is_computed_again(tmp_path, damage):
    cache = StudyCache(ResultCache(tmp_path))
    config = load_config(STAGE)
    first = study(config, parts=CHEAP, cache=cache)
    (entry,) = cache.store.entries()
    data = entry.read_bytes()
    if damage == "flip":
        entry.write_bytes(data[:-10] + bytes([data[-10] ^ 1]) + data[-9:])
    elif damage == "truncate":
        entry.write_bytes(data[: len(data) // 2])
    elif damage == "not_a_pickle":
        cache.store.write(first.cache_key, "study", b"not a pickle")
    elif damage == "not_parts":
        cache.store.write(first.cache_key, "study", pickle.dumps({"plots": 1}))
    else:
        entry.write_bytes(b"")
    again = study(config, parts=CHEAP, cache=cache)
    assert again.cached == frozenset() and _same(again.configured, first.configured)
    assert study(config, parts=CHEAP, cache=cache).cached == first.parts  # kept again


def test_no_cache_neither_reads_nor_keeps(tmp_path, monkeypatch, capsys):
    import bwdesign.report.certified as certified
    import bwdesign.testing.checks as checks

    seen = []

    def fake_report(config, out_dir, **kw):
        seen.append(kw["cache"])
        raise certified.InputError("stop here")

    monkeypatch.setattr(certified, "write_report", fake_report)
    monkeypatch.setenv("BWDESIGN_CACHE_DIR", str(tmp_path / "c"))
    for extra in ([], ["--no-cache"]):
        main(["report", "--config", str(CONFIG), "--out", str(tmp_path / "r"), *extra])
    assert isinstance(seen[0], StudyCache) and seen[0].store.root == tmp_path / "c"
    assert seen[1] is None
    real = checks.check_requirements
    monkeypatch.setattr(
        "bwdesign.cli.check.check_requirements",
        lambda f, cache: seen.append(cache) or real(f, cache=cache),
    )
    assert main(["check", str(STAGE), "--no-cache"]) == 0
    assert seen[2] is None and not (tmp_path / "c").exists()
    assert main(["check", str(STAGE)]) == 0
    assert isinstance(seen[3], StudyCache) and len(seen[3].store.entries()) == 1
    capsys.readouterr()


def test_the_cache_folder_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("BWDESIGN_CACHE_DIR", str(tmp_path / "a"))
    assert default_cache_dir() == tmp_path / "a"
    monkeypatch.delenv("BWDESIGN_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "xdg" / "bwdesign"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert default_cache_dir() == tmp_path / "home" / ".cache" / "bwdesign"


def test_the_store_reads_only_its_own_entries(tmp_path):
    store = ResultCache(tmp_path / "c")
    key = "ab" * 32
    assert store.read(key, "study") is None  # no folder yet
    assert store.write(key, "study", b"payload")
    assert store.read(key, "study") == b"payload"
    assert stat.S_IMODE(os.stat(store.root).st_mode) == 0o700
    path = store.path(key, "study")
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    os.chmod(path, 0o666)  # others could have written it: not trusted
    assert store.read(key, "study") is None
    os.chmod(path, 0o600)
    link = store.path("cd" * 32, "study")
    link.symlink_to(path)
    assert store.read("cd" * 32, "study") is None  # a symbolic link is not an entry
    with pytest.raises(ValueError):
        store.path("../x", "study")


def test_the_store_never_fails_and_never_touches_foreign_files(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    assert ResultCache(blocked / "c").write("ab" * 32, "study", b"x") is False
    store = ResultCache(tmp_path / "c")
    store.root.mkdir()
    foreign = [store.root / "notes.txt", store.root / ("ef" * 32 + ".study")]
    for f in foreign:
        f.write_bytes(b"mine")  # an entry's name, but not an entry
        os.chmod(f, 0o600)
    monkeypatch.setattr(store_mod, "MAX_ENTRIES", 3)
    for i in range(6):
        assert store.write(f"{i:064x}", "study", b"x")
    kept = sorted(p.name for p in store.entries())
    assert kept == [f"{i:064x}.study" for i in (3, 4, 5)]
    assert all(f.read_bytes() == b"mine" for f in foreign)
    assert not [p for p in store.root.iterdir() if p.name.startswith(".tmp-")]


def test_nothing_is_kept_after_ctrl_c(tmp_path, monkeypatch):
    from bwdesign import interrupts

    monkeypatch.setattr(interrupts, "pending", lambda: True)
    store = ResultCache(tmp_path)
    assert store.write("ab" * 32, "study", b"x") is False
    assert store.entries() == []


def test_check_and_report_share_one_entry_and_the_report_stays_the_same(computed, tmp_path):
    """``check`` adds the parts its requirements read to the report's entry; the report
    written from it afterwards is still the computed one."""
    from bwdesign.testing.checks import check_requirements

    cache, first = computed
    checks = check_requirements(load_config(CONFIG), cache=cache)
    assert checks and [p.suffix for p in cache.store.entries()].count(".study") == 1
    write_report(load_config(CONFIG), tmp_path / "after", quiet=True, date=DATE, cache=cache)
    assert _tree(tmp_path / "after") == first
    assert [c.line() for c in check_requirements(load_config(CONFIG), cache=cache)] == [
        c.line() for c in checks
    ]
