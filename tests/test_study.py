"""The computed study (issue 25, item 2): one frozen result behind the report, check and tests.

The report's own numbers are compared with the committed reports in
tests/test_report.py (and the bundled reports regenerate identically); here: what a
study is (parts asked, parts computed, frozen), that the checks read one study,
that the requirements' tracking is a study part, and the CLI's request objects.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from bwdesign import ClosedLoop, load_config, simulate_batch
from bwdesign.errors import ConfigError, InputError
from bwdesign.study import PARTS, REPORT_PARTS, Study, StudySettings, study
from bwdesign.study.compute import NEEDS

ROOT = Path(__file__).resolve().parents[1]
STAGE = ROOT / "examples" / "firmware_repo" / "stage.toml"
BOX = "\n[uncertainty]\na1 = { rel = 0.02 }\nalpha = { rel = 0.1 }\n"


def test_every_part_has_its_needs_and_the_report_all_but_the_requirements_ones():
    assert tuple(NEEDS) == PARTS
    # the requirements' corner tracking and the [baseline] check's analysis
    assert set(PARTS) - REPORT_PARTS == {"corner_tracking", "baseline"}


def test_a_part_not_asked_is_none_and_says_so():
    config = load_config(STAGE)
    s = study(config, parts={"loop", "sweep"})
    # "sweep" does not apply (no [sweep]): computed as None
    assert s.parts == {"loop", "sweep"}
    assert s.sweep is None and s.get("sweep") is None
    # without [uncertainty] the robust part is the nominal loop's certificate alone
    r = study(config, parts={"robust"})
    assert r.parts == {"envelope", "tuning", "robust"}
    assert r.robust.loops == () and [lp.observer for lp in r.robust.nominal] == ["phso", "phdo"]
    assert all(lp.certificate.holds for lp in r.robust.nominal)
    assert all(
        lp.certificate.tracking_bound >= lp.simulated_worst_maxe > 0 for lp in r.robust.nominal
    )
    assert s.loop.gains == config.gains and s.loop.sampled.dt == config.dt
    assert s.synthesis is None and s.tracking is None
    with pytest.raises(InputError, match=r"did not compute the part 'synthesis' \(computed: loop"):
        s.get("synthesis")
    with pytest.raises(InputError, match="unknown study part"):
        study(config, parts={"plots"})
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.loop = None


def test_a_part_brings_what_it_depends_on_and_progress_is_said_once():
    config = load_config(STAGE)
    said = []
    s = study(config, parts={"firmware"}, progress=said.append)
    assert s.parts == {"envelope", "configured", "synthesis", "firmware"}
    assert said == ["certifying the configured gains and synthesising a certified set"]
    assert s.firmware.configured_K == tuple(s.configured.discrete_gains)
    assert s.firmware.pole_matched == pytest.approx(s.firmware.configured_K, rel=1e-12)
    with pytest.raises(InputError, match="'input'"):
        s.to_dict()  # certificate.json needs every certificate part


def test_a_missing_section_is_named_for_the_parts_asked(tmp_path):
    text = STAGE.read_text().replace("[controller]\nlambda1 = 200.0\nlambda2 = 200.0\n", "")
    cfg = tmp_path / "stage.toml"
    cfg.write_text(text)
    config = load_config(cfg)
    with pytest.raises(ConfigError, match=r"the study \(loop\) needs section\(s\) \[controller\]"):
        study(config, parts={"loop"})
    with pytest.raises(ConfigError, match=r"the report needs section\(s\) \[controller\]"):
        study(config)
    assert study(config, parts={"configured"}).configured.certified  # needs no [controller]


def test_the_requirements_tracking_is_a_study_part_on_every_corner(tmp_path):
    """Nominal plant and every [uncertainty] corner, the [controller] law, in one batch."""
    cfg = tmp_path / "stage.toml"
    cfg.write_text(STAGE.read_text() + BOX)
    config = load_config(cfg)
    settings = StudySettings(noise_std=0.02, duration=0.4)
    part = study(config, parts={"corner_tracking"}, settings=settings).corner_tracking
    plants = [config.plant, *config.uncertainty.vertices(config.plant)]
    assert part.plants == len(plants) == 5 and part.duration == 0.4
    loop = ClosedLoop.from_config(config, start="reference")
    want = simulate_batch(loop, config.reference, plants, duration=0.4, noise_std=0.02, seeds=1)
    np.testing.assert_array_equal(part.result.maxe, want.maxe)
    np.testing.assert_array_equal(part.result.me, want.me)
    # the default settings are the stage's [requirements] (here: none of them set)
    assert study(config, parts={"plant"}).settings == StudySettings()


def test_check_requirements_reads_one_study(monkeypatch):
    import bwdesign.testing.checks as checks

    calls = []
    real = checks.study

    def counted(config, **kw):
        calls.append(kw["parts"])
        return real(config, **kw)

    monkeypatch.setattr(checks, "study", counted)
    out = checks.check_requirements(STAGE)
    assert len(out) == 6 and all(c.passed for c in out)
    assert calls == [{"configured", "corner_tracking", "loop"}]
    # the checks in the [requirements] schema's order
    assert [c.name for c in out] == [
        "certified",
        "min_decay",
        "max_me_um",
        "max_maxe_um",
        "min_gain_margin_db",
        "min_phase_margin_deg",
    ]


def test_render_needs_every_part_the_report_shows(tmp_path):
    from bwdesign.report.certified import render

    s = study(load_config(STAGE), parts={"plant"})
    with pytest.raises(InputError, match="the report needs the study's part"):
        render(s, tmp_path / "figures")
    with pytest.raises(InputError, match="must be a bwdesign Study"):
        render({"plant": None}, tmp_path / "figures")
    assert not (tmp_path / "figures").exists()
    assert isinstance(s, Study)


# -- the CLI builds one frozen request and leaves its namespace alone ------------------


def test_report_and_check_requests_do_not_touch_the_namespace(tmp_path, capsys):
    from bwdesign.cli.check import CheckRequest, run_check
    from bwdesign.cli.report import ReportRequest, run_report

    ns = argparse.Namespace(
        config=str(tmp_path / "missing.toml"),
        out=str(tmp_path / "out"),
        force=False,
        quiet=True,
        allow_unbounded=False,
    )
    before = dict(vars(ns))
    req = ReportRequest.from_args(ns)
    with pytest.raises(dataclasses.FrozenInstanceError):
        req.quiet = False
    with pytest.raises(ConfigError):
        run_report(ns)
    assert vars(ns) == before
    ns = argparse.Namespace(files=[str(tmp_path / "missing.toml")], junit_xml=None, json=False)
    before = dict(vars(ns))
    assert run_check(ns) == 2
    assert vars(ns) == before and CheckRequest.from_args(ns).files == tuple(ns.files)
    assert capsys.readouterr().err.startswith("error: ")


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"files": ()}, "at least one stage file"),
        ({"files": "stage.toml"}, "sequence of paths"),
        ({"files": ("a.toml",), "junit_xml": 3}, "--junit-xml must be a path"),
    ],
)
def test_check_request_is_validated(kwargs, message):
    from bwdesign.cli.args import UsageError
    from bwdesign.cli.check import CheckRequest

    with pytest.raises(UsageError, match=message):
        CheckRequest(**kwargs)
