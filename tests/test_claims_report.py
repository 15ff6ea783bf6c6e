"""Issue 19, the report's claims: unbounded stages, reproducible runs, saturation, units.

Each test here failed on the commit the issue was filed against (16f545d).
"""

import json
import re
from pathlib import Path

import pytest
from conftest import once

from bwdesign.cli.main import main
from bwdesign.design.tuning import digital_tuning
from bwdesign.errors import UnboundedModelError
from bwdesign.model.config import load_config
from bwdesign.study import CERTIFICATE_PARTS, study

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "paper_experiment.toml"
TEXT = CONFIG.read_text()


def _config(tmp_path, name, text):
    f = tmp_path / name
    f.write_text(text)
    return f


def tracking_runs(config, **kw):
    """The report's runs (imported here: the module is new, the other tests run without it)."""
    from bwdesign.study.tracking import tracking_runs as runs

    return runs(config, **kw)


def _fmt4(x):
    return f"{float(x):.4g}"


# -- item 2: report --allow-unbounded reaches certify and synthesize ----------------

UNBOUNDED = TEXT.replace("beta = 0.3762", "beta = -1.3567").replace(
    "from_reference = true\nmargin = 1.1", "udot_max = 400.0"
)


def test_report_allow_unbounded_is_passed_through(tmp_path, capsys):
    cfg = _config(tmp_path, "unbounded.toml", UNBOUNDED)
    config = load_config(cfg)
    with pytest.raises(UnboundedModelError):
        study(config, parts=CERTIFICATE_PARTS)
    out = tmp_path / "out"
    assert main(["report", "--config", str(cfg), "--out", str(out), "--quiet"]) == 2
    _, err = capsys.readouterr()
    assert "--allow-unbounded" in err and not out.exists()
    code = main(["report", "--config", str(cfg), "--out", str(out), "--quiet", "--allow-unbounded"])
    assert code in (0, 1) and (out / "report.md").is_file()


# -- item 3: the report says what it simulated, and each run can be rerun -----------


@pytest.fixture(scope="module")
def report_runs(paper_tuning_session):
    """The report's tracking runs, computed again here (the report's own are files)."""
    config = load_config(CONFIG)
    return tracking_runs(config, gains=config.gains, tuning=paper_tuning_session)


@pytest.fixture
def paper(paper_report, report_runs):
    """The paper_experiment report (conftest: written once per run) and its runs."""
    return paper_report.md, paper_report.cert, report_runs


def test_report_states_the_initial_state(paper):
    md, _, runs = paper
    assert "from rest" not in md
    s = runs[0].result.settings
    assert s["x0"] == s["xhat0"] == [100.0, pytest.approx(502.6548245743669, rel=1e-15), 0.0]
    assert "starting on the reference: plant state and estimate x0 = (100, 502.655, 0)" in md
    assert f"feedforward input {s['u_prev']:.6g} V held before t = 0" in md


def test_report_commands_reproduce_its_runs(paper, capsys):
    md, _, runs = paper
    assert len(runs) == 6
    for run in runs:
        assert run.command_text in md, run.label
        r = run.result
        row = f"| {run.label} | {_fmt4(r.metrics.maxe)} | {_fmt4(r.metrics.me)} |"
        assert row in md, run.label
        assert main(list(run.command) + ["--json"]) == 0
        out, err = capsys.readouterr()
        assert err == ""
        got = json.loads(out)
        assert got["start"] == "on reference"
        for k in ("maxe", "me", "rmse"):
            assert got["metrics"][k] == pytest.approx(getattr(r.metrics, k), rel=1e-9, abs=1e-12)
        assert got["estimation_rmse"]["x3"] == pytest.approx(r.estimation_rmse[2], abs=1e-9)


def test_report_runs_the_phdo_with_gains_from_the_one_helper(paper, paper_tuning):
    """{eq. 12, digital tuning} x {PHSO, ESO, PHDO}; the PHDO's gains are (l1, l2, 0, l3)."""
    from bwdesign.observers.gains import disturbance_gains_from

    md, _, runs = paper
    tuning = paper_tuning  # digital_tuning(config.plant, config.dt)
    labels = [run.label for run in runs]
    assert labels == [
        f"{o} ({law})" for law in ("eq. 12", "digital tuning") for o in ("PHSO", "ESO", "PHDO")
    ]
    want = {
        "PHDO (eq. 12)": (8.0, 64.0, 0.0, -512.0),
        "PHDO (digital tuning)": tuning.observer_gains_for("phdo"),
    }
    assert want["PHDO (digital tuning)"] == disturbance_gains_from(tuning.gains)
    for run in runs:
        gains = tuple(float(g) for g in run.command[run.command.index("--gains") + 1].split(","))
        assert tuple(run.result.settings["gains"]) == pytest.approx(gains, rel=1e-15)
        if run.label in want:
            assert run.command[run.command.index("--observer") + 1] == "phdo"
            assert gains == pytest.approx(want[run.label], rel=1e-15)
            g = ", ".join(f"{v:.6g}" for v in want[run.label])
            assert f"{run.label}: ({g})" in md
            assert f"| {run.label} | {_fmt4(run.result.metrics.maxe)} |" in md
    assert "bwdesign.observers.gains.disturbance_gains_from" in md


def test_simulate_from_rest_is_the_default_and_said(capsys):
    argv = ["simulate", "--plant", str(CONFIG), "--duration", "0.2"]
    assert main(argv) == 0
    out, _ = capsys.readouterr()
    assert "start: from rest, x0 = xhat0 = (0, 0, 0), u = 0 V before t = 0" in out
    assert main(argv + ["--start-on-reference"]) == 0
    out, _ = capsys.readouterr()
    assert "start: on the reference, x0 = xhat0 = (100, 502.655, 0)" in out


# -- items 4 and 5: input limits, saturation and units -------------------------------
# One report serves both: a stage in mV (item 5) whose limits 0 .. 10 mV the
# reference's feedforward input leaves (item 4).

MILLIVOLT = (
    TEXT.replace('input_unit = "V"', 'input_unit = "mV"')
    if 'input_unit = "V"' in TEXT
    else TEXT.replace('name = "paper_experiment"', 'name = "paper_experiment"\ninput_unit = "mV"')
)
SATURATING = MILLIVOLT.replace("lambda2 = 2.0", "lambda2 = 2.0\nu_min = 0.0\nu_max = 10.0")


@pytest.fixture(scope="module")
def saturating_report(tmp_path_factory):
    """``bwdesign report`` of the saturating mV stage, run once per test run (conftest)."""

    def build(base):
        base.mkdir(parents=True)
        cfg = _config(base, "sat.toml", SATURATING)
        code = main(["report", "--config", str(cfg), "--out", str(base / "out"), "--quiet"])
        (base / "code").write_text(str(code))

    base = once(tmp_path_factory, "saturating_report", build)
    md = (base / "out" / "report.md").read_text()
    cert = json.loads((base / "out" / "certificate.json").read_text())
    return base / "sat.toml", int((base / "code").read_text()), md, cert


def test_saturation_qualifies_the_verdict_and_exit_code(saturating_report):
    cfg, code, md, cert = saturating_report
    assert code == 1
    top = md.splitlines()[2]
    assert not top.startswith("> **CERTIFIED")
    assert top.startswith("> **OBSERVER CERTIFIED, REFERENCE OUT OF INPUT LIMITS")
    inp = cert["input"]
    assert inp["limits"] == [0.0, 10.0] and inp["within_limits"] is False
    lo, hi = inp["feedforward_range"]
    assert hi > 10.0
    assert f"feedforward input {lo:.4g} .. {hi:.4g} mV, outside the input limits 0 .. 10 mV" in top
    assert "| input limits ([controller] u_min, u_max) | 0 .. 10 mV |" in md
    config = load_config(cfg)
    runs = tracking_runs(config, gains=config.gains, tuning=digital_tuning(config.plant, config.dt))
    sat = [100 * run.result.saturated_fraction for run in runs]
    assert f"saturate {min(sat):.3g} to {max(sat):.3g} % of the time" in top
    for run, pct in zip(runs, sat, strict=True):
        assert pct > 50
        assert re.search(rf"\| {re.escape(run.label)} \|.*\| {pct:.3g} \|", md), run.label
        assert "--u-min 0.0 --u-max 10.0" in run.command_text


def test_units_follow_the_stage(saturating_report, capsys):
    cfg, _, md, cert = saturating_report
    for pattern in (r"(?<![m\w])V/s", r"/V\b", r"\(V s\^2\)", r"\d V\b"):
        assert not re.search(pattern, md), pattern
    assert "um/(mV s^2)" in md and "396.9 mV/s" in md
    assert cert["units"]["input"] == "mV" and cert["units"]["udot_max"] == "mV/s"
    capsys.readouterr()
    assert main(["certify", "--plant", str(cfg), "--udot-max", "100", "--json"]) == 0
    assert json.loads(capsys.readouterr()[0])["units"]["udot_max"] == "mV/s"
    assert main(["certify", "--plant", str(cfg), "--udot-max", "100"]) == 0
    text, _ = capsys.readouterr()
    assert "max |u_dot| (mV/s)" in text and "<= 100 mV/s" in text
    assert main(["simulate", "--plant", str(cfg), "--duration", "0.2", "--json"]) == 0
    assert json.loads(capsys.readouterr()[0])["input_unit"] == "mV"


def test_plots_label_the_input_unit():
    from bwdesign import ClosedLoop, ObserverSpec, Sine, make_controller, simulate
    from bwdesign.model.params import preset
    from bwdesign.plotting import figures

    p = preset("paper_experiment")
    mv = type(p)(
        **{
            **{k: getattr(p, k) for k in ("a1", "a2", "a3", "alpha", "beta", "gamma")},
            "input_unit": "mV",
        }
    )
    loop = ClosedLoop(
        mv, ObserverSpec.of("phso", (8, 64, -512)), make_controller(mv, 1, 2), dt=2e-4
    )
    r = simulate(loop, Sine(amplitude=10, offset=10, frequency=5), duration=0.2)
    _, axes = figures.plot_tracking_comparison({"PHSO": r})
    assert axes[2, 0].get_ylabel() == "control input u (mV)"
    _, axes = r.plot()
    assert axes[2, 0].get_ylabel() == "u (mV)"


# -- item 7: the certificate table and stderr --------------------------------------


def test_certificate_table_labels_both_decays(paper):
    md, cert, _ = paper
    c, s = cert["configured"]["decay"], cert["synthesized"]["decay"]
    assert c != s  # the two sets are certified at different required decays ...
    header = next(line for line in md.splitlines() if line.startswith("| tier |"))
    assert f"configured (decay >= {c:g} 1/s): holds" in header  # ... and the table says so
    assert f"synthesised (decay >= {s:g} 1/s): holds" in header
    assert "lipschitz envelope at decay 0:" in md


@pytest.mark.parametrize(
    "label, text, allow",
    [
        ("unbounded", TEXT.replace("beta = 0.3762", "beta = -1.3567"), False),
        ("bad gains", TEXT.replace("-512.0]", "512.0]"), False),
    ],
)
def test_report_exit_2_prints_only_the_error_line(tmp_path, capsys, label, text, allow):
    cfg = _config(tmp_path, "bad.toml", text)
    out = tmp_path / "out"
    argv = ["report", "--config", str(cfg), "--out", str(out)]  # progress lines on
    assert main(argv + (["--allow-unbounded"] if allow else [])) == 2
    stdout, err = capsys.readouterr()
    assert stdout == ""
    assert len(err.splitlines()) == 1 and err.startswith("error: "), err
