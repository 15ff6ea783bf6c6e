"""Several records in one fit: one parameter set, an offset and an initial state per record.

Two seeded records of the same truth (the package's ``simulate_zoh`` on
``paper_experiment``), logged at 200 Hz and 2 kHz with different amplitudes,
frequencies and sensor offsets, both started mid-cycle.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from bwdesign import identify, load_config, preset, simulate_zoh
from bwdesign.cli.main import main
from bwdesign.identify import IdentificationData
from bwdesign.output.jsonenc import dump_json

NAMES = ("a1", "a2", "a3", "alpha", "beta", "gamma")
PLANT = preset("paper_experiment")
OFFSETS = (7.0, -4.0)


def _record(u_of_t, fs, seconds, *, offset, seed, pre, source):
    dt = 1.0 / fs
    n_pre, n = int(round(pre * fs)), int(round(seconds * fs))
    t = np.arange(n_pre + n) * dt
    u = u_of_t(t)
    x = simulate_zoh(PLANT, u, dt, np.zeros(3), u_prev=u[0])[1 + n_pre :, 0]
    y = x + offset + 0.01 * np.random.default_rng(seed).standard_normal(n)
    return IdentificationData.from_arrays(t[:n], u[n_pre:], y, source=source)


def _slow(t):
    return 60.0 + 50.0 * np.sin(2 * np.pi * t + 0.4)


def _minor(t):
    return 50.0 + 30.0 * np.sin(2 * np.pi * 2.5 * t) + 5.0 * np.sin(2 * np.pi * 11.0 * t)


@pytest.fixture(scope="module")
def records():
    a = _record(_slow, 200.0, 6.0, offset=OFFSETS[0], seed=11, pre=1.3, source="a")
    b = _record(_minor, 2000.0, 2.0, offset=OFFSETS[1], seed=13, pre=0.37, source="b")
    return a, b


@pytest.fixture(scope="module")
def fits(records):
    a, b = records
    return identify(a), identify(b), identify([a, b])


def test_joint_fit_recovers_offsets_and_truth(records, fits):
    *singles, joint = fits
    assert joint.converged, joint.reason
    assert [r["dt"] for r in joint.records] == [0.005, 0.0005]  # two sample rates, one fit
    assert joint.n_samples == sum(r.n for r in records)
    for rec, truth, single in zip(joint.records, OFFSETS, singles, strict=True):
        assert abs(rec["offset"] - truth) < 3 * rec["offset_std_err"] + 1e-3, rec
        assert rec["fit_percent"] > 99.9
        # the record's own fit is as good jointly as alone (same truth)
        assert rec["fit_percent"] > single.fit_percent["train"] - 0.01
    assert joint.offset == joint.records[0]["offset"]
    for n in NAMES:
        if joint.determined[n]:
            lo, hi = joint.ci95[n]
            assert lo <= getattr(PLANT, n) <= hi, (n, joint.ci95[n], getattr(PLANT, n))
    assert {n for n in NAMES if joint.determined[n]} >= {"alpha", "beta", "gamma"}


def test_joint_intervals_no_wider_than_either_single_fit(fits):
    *singles, joint = fits
    for n in NAMES:
        if joint.determined[n]:
            for single in singles:
                assert joint.std_err[n] <= single.std_err[n], (n, joint.std_err, single.std_err)
    for key in ("static_gain", "lag"):
        for single in singles:
            assert joint.derived[key]["std_err"] <= single.derived[key]["std_err"]


def test_one_record_as_a_list_is_the_single_fit(records, fits):
    a = records[0]
    listed = identify([a])
    same = [dump_json(r.to_dict() | {"seconds": 0}) for r in (listed, fits[0])]
    assert same[0] == same[1]
    assert "records" not in listed.to_dict()


def test_joint_json_and_validation_records(records, fits):
    a, b = records
    res = identify([a], validation=[a, b])  # validation at another sample rate is accepted
    doc = res.to_dict()
    assert [v["source"] for v in doc["validation_records"]] == ["a", "b"]
    assert all(v["fit_percent"] > 99.0 for v in doc["validation_records"])
    joint = fits[2].to_dict()
    assert [r["source"] for r in joint["records"]] == ["a", "b"]
    assert set(joint["records"][0]) >= {"fit_percent", "offset", "offset_std_err", "initial_state"}


def _csv(path, rec, bad_row=None):
    lines = ["t,u,y"] + [
        ",".join(repr(float(v)) for v in row) for row in zip(rec.t, rec.u, rec.y, strict=True)
    ]
    if bad_row is not None:
        lines[bad_row] = lines[bad_row].rsplit(",", 1)[0] + ",nan"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def test_cli_two_records_stage_report_json(tmp_path, capsys, records):
    a = _csv(tmp_path / "a.csv", records[0])
    b = _csv(tmp_path / "b.csv", records[1])
    out, rep = tmp_path / "stage.toml", tmp_path / "rep"
    args = ["identify", "--data", a, "--data", b, "--out", str(out), "--report", str(rep)]
    rc = main([*args, "--quiet", "--json"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    doc = json.loads(cap.out)
    assert [r["source"] for r in doc["records"]] == [a, b]
    assert load_config(out).plant.alpha > 0
    text = out.read_text()
    assert "2 records fitted together" in text and b in text
    assert "| training | `" + b in (rep / "report.md").read_text()


def test_cli_bad_row_in_second_file_names_it(tmp_path, capsys, records):
    a = _csv(tmp_path / "a.csv", records[0])
    b = _csv(tmp_path / "b.csv", records[1], bad_row=7)
    out = tmp_path / "stage.toml"
    rc = main(["identify", "--data", a, "--data", b, "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("error:") and b in err[0] and "row 7" in err[0]
    assert not out.exists()


def test_a_record_that_sees_the_resonance_frees_it_for_all(records):
    """A slow sine alone cannot place the resonance; with a multisine record it is fitted."""
    from bwdesign.identify.excite import design_excitation

    fs = 5000.0
    _, u = design_excitation(
        PLANT, umin=0, umax=120, udot_max=2000, duration=0.6, dt=1 / fs, seed=2
    )
    x = simulate_zoh(PLANT, u, 1 / fs, np.zeros(3), u_prev=u[0])[1:, 0]
    y = x + 3.0 + 0.01 * np.random.default_rng(5).standard_normal(u.size)
    ms = IdentificationData.from_arrays(np.arange(u.size) / fs, u, y, source="multisine")
    joint = identify([records[0], ms])
    assert joint.converged, joint.reason
    assert joint.determined["a1"] and joint.determined["a2"]
    for n in ("a1", "a2", "a3"):
        lo, hi = joint.ci95[n]
        assert lo <= getattr(PLANT, n) <= hi, (n, joint.ci95[n])
