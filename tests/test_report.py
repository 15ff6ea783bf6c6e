"""The certified-gains report: content, determinism, atomic writing, bad configs."""

import json
from pathlib import Path

import pytest

from bwdesign.cli.main import main
from bwdesign.model.config import load_config
from bwdesign.output.jsonenc import dump_json
from bwdesign.report.certified import certificate_document, write_report

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "paper_experiment.toml"
COMMITTED = ROOT / "reports" / "paper_experiment"
DATE = "2000-01-01 00:00 UTC"

#: Tolerance of the committed-JSON comparison. Gains, discrete gains and
#: decay rates come from deterministic solvers and closed forms and must agree
#: to 1e-6 relative; envelopes come from a bisection with 1 % resolution and
#: may move by one step (2 %) if a solver's last digits change.
RTOL_VALUES = 1e-6
RTOL_ENVELOPE = 0.02


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    base = tmp_path_factory.mktemp("reports")
    config = load_config(CONFIG)
    first = write_report(config, base / "a", quiet=True, date=DATE)
    second = write_report(config, base / "b", quiet=True, date=DATE)
    return first, second


def test_report_files_and_verdict(built):
    first, _ = built
    out = first.out_dir
    for name in ("report.md", "report.html", "certificate.json"):
        assert (out / name).is_file()
    figures = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert len(figures) >= 5
    md = (out / "report.md").read_text()
    assert first.certified
    assert md.splitlines()[2].startswith("> **CERTIFIED")
    # the paper's gains and a synthesised set side by side, tier by tier
    assert "Configured gains l = (8, 64, -512)" in md
    for tier in ("theorem1", "lipschitz", "sector", "sampled"):
        assert f"| {tier} |" in md
    for fig in figures:
        assert f"figures/{fig}" in md
    assert "config sha256" in md and load_config(CONFIG).sha256 in md


def test_two_runs_are_identical(built):
    a, b = built
    for name in ("report.md", "certificate.json"):
        assert (a.out_dir / name).read_bytes() == (b.out_dir / name).read_bytes(), name


def _compare(new, old, path=""):
    if isinstance(old, dict):
        assert set(new) == set(old), path
        for k in old:
            if k in ("P", "margins", "solver", "status", "reason", "details"):
                continue
            _compare(new[k], old[k], f"{path}.{k}")
    elif isinstance(old, list):
        assert len(new) == len(old), path
        for i, (n, o) in enumerate(zip(new, old, strict=True)):
            _compare(n, o, f"{path}[{i}]")
    elif isinstance(old, float) and not isinstance(old, bool):
        rtol = RTOL_ENVELOPE if "max_udot" in path else RTOL_VALUES
        assert new == pytest.approx(old, rel=rtol, abs=1e-12), path
    else:
        assert new == old, path


def test_committed_certificate_json_is_current():
    """Regenerate certificate.json and compare with the committed one (tolerances above)."""
    committed = json.loads((COMMITTED / "certificate.json").read_text())
    doc, _, _ = certificate_document(load_config(CONFIG))
    fresh = json.loads(dump_json(doc))
    _compare(fresh, committed)


def test_not_certified_is_a_well_formed_no(tmp_path, capsys):
    """Far above the paper gains' envelope nothing holds: report written, exit 1."""
    text = CONFIG.read_text().replace("from_reference = true\nmargin = 1.1", "udot_max = 1.0e5")
    cfg = tmp_path / "fast.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    code = main(["report", "--config", str(cfg), "--out", str(out), "--quiet"])
    assert code == 1
    md = (out / "report.md").read_text()
    assert md.splitlines()[2].startswith("> **NOT CERTIFIED")
    cert = json.loads((out / "certificate.json").read_text())
    assert cert["configured"]["certified"] is False
    assert cert["synthesis"]["feasible"] is True


GOOD = CONFIG.read_text()
BAD = [
    ("missing section", GOOD.replace("[sampling]\ndt = 0.0002", ""), "needs section(s) [sampling]"),
    (
        "unknown key",
        GOOD.replace("lambda2 = 2.0", "lambda2 = 2.0\nlambda3 = 1.0"),
        "unknown key(s) lambda3; allowed keys are lambda1, lambda2, u_max, u_min",
    ),
    ("wrong type", GOOD.replace("lambda1 = 1.0", 'lambda1 = "one"'), "lambda1 must be a number"),
    (
        "envelope not positive",
        GOOD.replace("from_reference = true\nmargin = 1.1", "udot_max = -5.0"),
        "positive number",
    ),
    (
        "envelope not a number",
        GOOD.replace("from_reference = true\nmargin = 1.1", 'udot_max = "fast"'),
        "must be a number",
    ),
]


@pytest.mark.parametrize("label, text, message", BAD, ids=[b[0] for b in BAD])
def test_bad_configs(tmp_path, capsys, label, text, message):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    code = main(["report", "--config", str(cfg), "--out", str(out), "--quiet"])
    _, err = capsys.readouterr()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("error: ") and message in err
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [cfg]  # no temporary directory left behind


def test_failure_leaves_existing_report_untouched(tmp_path, monkeypatch):
    from bwdesign.output.files import prepare_directory

    out = tmp_path / "out"
    with prepare_directory(out, command="report").stage() as stage:  # a previous report
        stage.write_text("report.md", "previous")
    import bwdesign.report.certified as report

    def boom(*a, **k):
        raise RuntimeError("simulated crash")

    monkeypatch.setattr(report, "build_report", boom)
    with pytest.raises(RuntimeError):
        write_report(load_config(CONFIG), out, quiet=True)
    assert (out / "report.md").read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
