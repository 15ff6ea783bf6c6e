"""Identification input and output: the bad-data table and the commands.

The [uncertainty] box they write is tested in tests/test_uncertainty.py.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from bwdesign import InputError, load_config, preset
from bwdesign.cli.main import main  # in-process; the console script's leaves SIGINT ignored
from bwdesign.identify import MIN_SAMPLES, load_data
from bwdesign.identify.excite import (
    RANGE_MARGIN,
    design_excitation,
    simulate_record,
    smallest_rate,
)

GOOD_T = np.arange(400) * 1e-3
GOOD_U = 5 + 4 * np.sin(2 * np.pi * 5 * GOOD_T)
GOOD_Y = 1.4 * GOOD_U


def _csv(path, header, rows):
    path.write_text(header + "\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n")
    return path


def _rows(t=GOOD_T, u=GOOD_U, y=GOOD_Y):
    return list(zip(t, u, y, strict=True))


def _with(rows, i, col, value):
    rows = [list(r) for r in rows]
    rows[i][col] = value
    return rows


#: The bad-data table: each case, and the error message it gets (InputError, exit 2).
BAD = [
    ("missing_column", "t,u,z", _rows(), r"missing column\(s\) y"),
    ("non_numeric", "t,u,y", _with(_rows(), 7, 1, "abc"), r"non-numeric value 'abc' in column u"),
    (
        "nan_row",
        "t,u,y",
        _with(_rows(), 9, 2, "nan"),
        r"NaN or infinite values, first at data row 10",
    ),
    ("inf_row", "t,u,y", _with(_rows(), 3, 1, "inf"), r"NaN or infinite"),
    ("non_increasing", "t,u,y", _with(_rows(), 5, 0, 0.001), r"t is not increasing"),
    (
        "non_uniform",
        "t,u,y",
        _with(_rows(), 50, 0, 0.0503),
        r"not uniformly sampled.*tolerance 0.1 %",
    ),
    (
        "gap_in_t",
        "t,u,y",
        _rows(t=np.concatenate((GOOD_T[:120], GOOD_T[125:] + 0.0)), u=GOOD_U[:395], y=GOOD_Y[:395]),
        r"a gap in t between data rows 120 and 121.*about 5 missing sample",
    ),
    ("too_few", "t,u,y", _rows()[: MIN_SAMPLES - 1], rf"needs at least {MIN_SAMPLES}"),
    ("input_never_moves", "t,u,y", _rows(u=np.full(400, 2.0)), r"input u never moves"),
    ("output_never_moves", "t,u,y", _rows(y=np.zeros(400)), r"output y never moves"),
    ("short_row", "t,u,y", [*_rows()[:300], (0.3,)], r"has no value for column u"),
]


@pytest.mark.parametrize("header,rows,match", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_data_table(tmp_path, header, rows, match):
    path = _csv(tmp_path / "d.csv", header, rows)
    with pytest.raises(InputError, match=match):
        load_data(path)


CLI_BAD = [b for b in BAD if b[0] in ("missing_column", "non_numeric", "nan_row", "gap_in_t")]


@pytest.mark.parametrize("header,rows,match", [b[1:] for b in CLI_BAD], ids=[b[0] for b in CLI_BAD])
def test_bad_data_exit_2_nothing_written(tmp_path, capsys, header, rows, match):
    path = _csv(tmp_path / "d.csv", header, rows)
    out = tmp_path / "stage.toml"
    assert main(["identify", "--data", str(path), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and err.count("\n") == 1
    assert not out.exists()


def test_columns_mapping_extra_columns_and_npz(tmp_path):
    rows = [(a, b, c, 0.0) for a, b, c in _rows()]
    path = _csv(tmp_path / "d.csv", "# a comment line\ntime,volts,extra,um", [])
    path.write_text(
        "# a comment line\ntime,volts,um,extra\n"
        + "\n".join(f"{a},{b},{c},{d}" for a, b, c, d in rows)
        + "\n"
    )
    rec = load_data(path, columns="time,volts,um")
    assert rec.n == 400 and rec.dt == pytest.approx(1e-3)
    np.savez(tmp_path / "d.npz", t=GOOD_T, u=GOOD_U, y=GOOD_Y)
    assert load_data(tmp_path / "d.npz").n == 400
    with pytest.raises(InputError, match="missing array"):
        load_data(tmp_path / "d.npz", columns="t,u,disp")
    with pytest.raises(InputError, match="does not exist"):
        load_data(tmp_path / "nope.csv")


# -- commands --------------------------------------------------------------------


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    plant = preset("paper_experiment")
    for name, kind, seed in (("train", "multisine", 0), ("valid", "triangle-sweep", 3)):
        assert (
            main(
                [
                    "excite",
                    "--plant",
                    "paper_experiment",
                    "--kind",
                    kind,
                    "--umin",
                    "0",
                    "--umax",
                    "120",
                    "--udot-max",
                    "2000",
                    "--duration",
                    "0.5",
                    "--dt",
                    "2e-4",
                    "--seed",
                    str(seed),
                    "--simulate-noise",
                    "0.01",
                    "--offset",
                    "3",
                    "--out",
                    str(d / f"{name}.csv"),
                ]
            )
            == 0
        )
    return d, plant


def test_excite_respects_range_and_rate(records, capsys):
    d, _ = records
    text = (d / "train.csv").read_text()
    assert text.startswith("# written by bwdesign")
    assert "SIMULATED, NOT MEASURED" in text and "Regenerate: bwdesign excite" in text
    rec = load_data(d / "train.csv")
    # the range asked, to within RANGE_MARGIN of each end (it used 31-90 V of 0-120 V)
    margin = RANGE_MARGIN * 120
    assert rec.u.min() == pytest.approx(margin) and rec.u.max() == pytest.approx(120 - margin)
    assert np.max(np.abs(np.diff(rec.u))) / rec.dt <= 2000 * (1 + 1e-9)
    for kind in ("multisine", "triangle-sweep"):
        t, u = design_excitation(
            preset("paper_simulation_corrected"),
            kind=kind,
            umin=-1,
            umax=7,
            udot_max=5e3,
            duration=0.05,
            dt=1e-5,
        )
        assert u.min() == pytest.approx(-1 + 8 * RANGE_MARGIN)
        assert u.max() == pytest.approx(7 - 8 * RANGE_MARGIN)
        assert np.max(np.abs(np.diff(u))) <= 5e3 * 1e-5 * 1.000001


@pytest.mark.parametrize("kind", ["multisine", "triangle-sweep"])
def test_excite_uses_the_range_down_to_the_smallest_rate(kind):
    """Seeded random ranges, lengths and rates from the smallest usable one up: the input spans
    the range to within RANGE_MARGIN of each end, keeps the rate, and below it is refused."""
    rng = np.random.default_rng(24)
    plant = preset("paper_experiment")
    for _ in range(25):
        lo = rng.uniform(-100, 100)
        hi = lo + 10 ** rng.uniform(-1, 3)
        duration, n = 10 ** rng.uniform(-1.5, 0.5), int(10 ** rng.uniform(2.4, 3.7))
        kw = dict(umin=lo, umax=hi, duration=duration, dt=duration / n)
        need = smallest_rate(kind=kind, **kw)
        udot = need * (1 + 10 ** rng.uniform(-4, 2))
        _, u = design_excitation(plant, kind=kind, udot_max=udot, **kw)
        m = RANGE_MARGIN * (hi - lo)
        assert u.min() == pytest.approx(lo + m, abs=1e-9 * (hi - lo))
        assert u.max() == pytest.approx(hi - m, abs=1e-9 * (hi - lo))
        assert np.max(np.abs(np.diff(u))) <= udot * kw["dt"] * (1 + 1e-9)
        with pytest.raises(
            InputError, match=re.escape(f"below the smallest usable {need:.4g} V/s")
        ):
            design_excitation(plant, kind=kind, udot_max=need * 0.999, **kw)


def test_identify_command_writes_a_stage_every_command_accepts(records, capsys, tmp_path):
    d, plant = records
    out = tmp_path / "stage.toml"
    rc = main(
        [
            "identify",
            "--data",
            str(d / "train.csv"),
            "--validate",
            str(d / "valid.csv"),
            "--out",
            str(out),
            "--json",
            "--multistart",
            "1",
        ]
    )
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert "identify:" in cap.err  # progress on stderr
    doc = json.loads(cap.out)
    assert set(doc["params"]) == {"a1", "a2", "a3", "alpha", "beta", "gamma"}
    assert set(doc["fit_percent"]) >= {"train", "validation"}
    assert doc["fit_percent"]["validation"] > 99.5
    assert doc["residual_rms"] == pytest.approx(0.01, rel=0.15)
    for n, (lo, hi) in doc["ci95"].items():
        assert lo < doc["params"][n] < hi
    cfg = load_config(out)
    assert cfg.dt == pytest.approx(2e-4)
    assert cfg.uncertainty is not None and cfg.uncertainty.source == "identified"
    assert abs(cfg.plant.a1 / plant.a1 - 1) < 0.01
    assert cfg.envelope() is not None and cfg.controller is not None
    assert main(["params", "--plant", str(out), "--json"]) == 0
    # a second run may replace bwdesign's own file, never a user's
    user = tmp_path / "mine.toml"
    user.write_text("[plant]\n")
    rc = main(["identify", "--data", str(d / "train.csv"), "--out", str(user), "--quiet"])
    assert rc == 2 and user.read_text() == "[plant]\n"
    assert "bwdesign never overwrites other files" in capsys.readouterr().err


def test_identify_not_converged_exit_1(records, capsys, tmp_path):
    d, _ = records
    out = tmp_path / "s.toml"
    rc = main(
        [
            "identify",
            "--data",
            str(d / "train.csv"),
            "--out",
            str(out),
            "--quiet",
            "--multistart",
            "1",
            "--max-nfev",
            "1",
        ]
    )
    assert rc == 1
    err = capsys.readouterr().err
    assert "did not converge" in err and "what would help" in err
    assert "best fit found (not written): train" in err
    assert not out.exists()


def test_simulated_record_with_amplifier_lag_differs():
    p = preset("paper_experiment")
    u = 10 + np.sin(np.arange(500) * 0.05)
    a = simulate_record(p, u, 2e-4, noise=0.0)
    b = simulate_record(p, u, 2e-4, noise=0.0, amplifier_lag=1e-3)
    assert 0 < np.max(np.abs(a.y - b.y)) < 0.5


def test_identify_report(records, capsys, tmp_path):
    d, _ = records
    out, rep = tmp_path / "stage.toml", tmp_path / "rep"
    args = ["identify", "--data", str(d / "train.csv"), "--out", str(out), "--quiet"]
    assert main([*args, "--multistart", "1", "--report", str(rep)]) == 0
    md = (rep / "report.md").read_text()
    for text in ("95 % interval", "Correlation matrix", "Hysteresis loop", "autocorrelation"):
        assert text in md
    html = (rep / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 3
    assert json.loads((rep / "identification.json").read_text())["converged"] is True
    # rerun replaces its own report; a foreign directory is refused
    assert main([*args, "--multistart", "1", "--report", str(rep)]) == 0
    foreign = tmp_path / "notes"
    foreign.mkdir()
    (foreign / "mine.txt").write_text("keep")
    assert main([*args, "--multistart", "1", "--report", str(foreign)]) == 2
    assert "pass --force" in capsys.readouterr().err
    assert (foreign / "mine.txt").read_text() == "keep"
    # --force (which the message names) writes beside the foreign file, never over it
    assert main([*args, "--multistart", "1", "--report", str(foreign), "--force"]) == 0
    assert (foreign / "mine.txt").read_text() == "keep" and (foreign / "report.md").is_file()
