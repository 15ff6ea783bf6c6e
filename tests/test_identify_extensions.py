"""Model extensions, the disturbance bound and the coverage on generated records with a
known truth (issue 26, Build 3).

(a) the base model: no extension chosen, the box contains the truth, the held-out
band covers the output; (b) a truth with creep and a 2 ms amplifier lag that the
base model lacks: both are chosen, the residual whitens, the held-out band covers.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from bwdesign import identify, load_config, preset, simulate_zoh
from bwdesign.cli.main import main
from bwdesign.identify import IdentificationData
from bwdesign.identify.excite import design_excitation
from bwdesign.identify.extstack import CREEP_TAUS, first_order_lag

PLANT = preset("paper_experiment")  # 64 Hz resonance, 1.39 um/V
NAMES = ("a1", "a2", "a3", "alpha", "beta", "gamma")


def _record(seed, seconds, *, fs=1000.0, amp_tau=0.0, creep=(0.0, 0.0, 0.0), noise=0.01):
    """A multisine record of PLANT, its input through an amplifier lag ``amp_tau`` (s) and
    the output with creep ``c_i K (L_i v - v)`` (``c_i`` relative to the static gain K)."""
    dt = 1.0 / fs
    _, u = design_excitation(
        PLANT, umin=0, umax=120, udot_max=2000, duration=seconds, dt=dt, seed=seed
    )
    v = first_order_lag(u, dt, amp_tau)
    x = simulate_zoh(PLANT, v, dt, np.zeros(3), u_prev=v[0])[1:, 0]
    for tau, c in zip(CREEP_TAUS, creep, strict=True):
        x = x + c * PLANT.static_gain * (first_order_lag(v, dt, tau) - v)
    y = x + 3.0 + noise * np.random.default_rng(seed + 100).standard_normal(u.size)
    return IdentificationData.from_arrays(np.arange(u.size) * dt, u, y, source=f"gen{seed}")


def _inside(res) -> list[bool]:
    return [res.ci95[n][0] <= getattr(PLANT, n) <= res.ci95[n][1] for n in NAMES]


def test_base_truth_keeps_extensions_off_and_is_covered():
    res = identify(_record(1, 4.0), validation=_record(2, 3.0))
    assert res.converged
    ext = res.extensions
    assert ext["chosen"] == []
    assert set(ext["candidates"]) == {"amplifier_lag", "creep", "drift"}
    assert all(not row["chosen"] and row["reason"] for row in ext["candidates"].values())
    assert res.coverage >= 0.95
    # the bound from the training record alone covers the held-out record as well
    assert res.unexplained["band"]["coverage_full_bound"] >= 0.95
    assert all(_inside(res))
    # the bound is small: what the model misses is noise (10 nm on a ~160 um stroke)
    assert 0 < res.disturbance.input_max < 0.05
    assert res.disturbance.source == "identified"


def _box_share(seeds) -> float:
    hits = [h for s in seeds for h in _inside(identify(_record(s, 3.0)))]
    return sum(hits) / len(hits)


def test_box_contains_truth_over_seeded_trials():
    # 3 trials x 6 parameters at the stated 95 %: allow one miss in 18
    assert _box_share((11, 12, 13)) >= 17 / 18 - 1e-12


@pytest.mark.slow
def test_box_contains_truth_campaign():
    assert _box_share(range(20, 40)) >= 0.9


def test_creep_and_amplifier_lag_are_chosen_and_whiten():
    truth = {"amp_tau": 2e-3, "creep": (0.03, 0.03, 0.04)}
    res = identify(_record(1, 10.0, **truth), validation=_record(2, 6.0, **truth))
    ext = res.extensions
    assert set(ext["chosen"]) == {"amplifier_lag", "creep"}
    assert ext["candidates"]["amplifier_lag"]["tau_s"] == pytest.approx(2e-3, rel=0.2)
    weights = np.array(ext["candidates"]["creep"]["weights"]) / PLANT.static_gain
    assert np.all(np.abs(weights - truth["creep"]) < 0.015)
    assert not ext["candidates"]["drift"]["chosen"]
    base, final = ext["base"], ext["final"]
    assert base["acf1"] > 0.9 and final["acf1"] < 0.2
    assert final["frac_out"] < base["frac_out"]
    assert final["fit_heldout"] > base["fit_heldout"] + 1.0
    assert res.coverage >= 0.95
    assert res.unexplained["band"]["coverage_full_bound"] >= 0.95
    # the Bouc-Wen part of the extended fit is the truth's, inside the box (the lag
    # fitted to 0.02 % of its profile minimum and the intervals marginal over it)
    assert res.params.static_gain == pytest.approx(PLANT.static_gain, rel=0.02)
    assert all(_inside(res))


def test_extensions_found_together_when_one_at_a_time_stays_biased():
    # 6 s, no validation record: the base fit takes a 3-sample input delay for the 2 ms
    # lag and flattens the hysteresis to follow the creep; from there no single
    # extension helps (the one-step screens predict a worse BIC), all of them together do
    res = identify(_record(11, 6.0, amp_tau=2e-3, creep=(0.06, 0.06, 0.0)))
    ext = res.extensions
    assert ext["base"]["acf1"] > 0.9
    assert set(ext["chosen"]) == {"amplifier_lag", "creep"}
    assert "together" in ext["candidates"]["creep"]["reason"]
    assert not ext["candidates"]["drift"]["chosen"]
    assert ext["candidates"]["amplifier_lag"]["tau_s"] == pytest.approx(2e-3, rel=0.02)
    assert res.delay_samples == 0
    weights = np.array(ext["candidates"]["creep"]["weights"]) / PLANT.static_gain
    assert np.all(np.abs(weights - (0.06, 0.06)) < 0.006)
    assert ext["final"]["acf1"] < 0.2
    assert all(_inside(res))


def test_lag_at_the_end_of_the_short_grid_is_rescored_fully():
    # with a fast creep chosen first, the short refits put a 2-sample lag at the
    # grid's first point ("not determined"); full refits find it
    res = identify(_record(11, 6.0, amp_tau=2e-3, creep=(0.1, 0.0, 0.0)))
    row = res.extensions["candidates"]["amplifier_lag"]
    assert row["chosen"] and row["tau_s"] == pytest.approx(2e-3, rel=0.02)
    assert all(_inside(res))


@pytest.mark.slow
def test_box_contains_truth_with_creep_and_lag_campaign():
    # 20 seeded 10 s records of a truth with creep and a 2 ms amplifier lag, no
    # validation record. Measured: 108 of 120 parameter-trial pairs (0.90) against the
    # stated 0.95; the misses come in whole trials (the lag ~2.5 standard errors off
    # moves all six together), so 0.85 guards against a regression, not the level
    truth = {"amp_tau": 2e-3, "creep": (0.03, 0.03, 0.04)}
    hits = [h for s in range(30, 50) for h in _inside(identify(_record(s, 10.0, **truth)))]
    assert sum(hits) / len(hits) >= 0.85


def _slow_sine(seconds=8.0, fs=200.0):
    t = np.arange(int(seconds * fs)) / fs
    u = 60.0 + 50.0 * np.sin(2 * np.pi * t + 0.4)
    v = first_order_lag(u, 1 / fs, 2e-3)
    x = simulate_zoh(PLANT, v, 1 / fs, np.zeros(3), u_prev=v[0])[1:, 0]
    y = x + 7.0 + 0.01 * np.random.default_rng(4).standard_normal(t.size)
    return IdentificationData.from_arrays(t, u, y, source="slow sine")


def test_undetermined_extension_is_reported_not_forced():
    # a 1 Hz sine far below the resonance: an amplifier lag is one more low-frequency
    # lag, indistinguishable from a2/a1
    res = identify(_slow_sine())
    row = res.extensions["candidates"]["amplifier_lag"]
    assert not row["chosen"]
    assert "not determined" in row["reason"] or "not needed" in row["reason"]
    assert "amplifier_lag" not in res.extensions["chosen"]


def test_cli_json_and_stage_file_carry_extensions_disturbance_coverage(tmp_path, capsys):
    for name, rec in (("tr", _record(1, 4.0)), ("va", _record(2, 3.0))):
        np.savetxt(
            tmp_path / f"{name}.csv",
            np.column_stack([rec.t, rec.u, rec.y]),
            delimiter=",",
            header="t,u,y",
            comments="",
        )
    out = tmp_path / "stage.toml"
    args = ["identify", "--data", str(tmp_path / "tr.csv"), "--validate", str(tmp_path / "va.csv")]
    rc = main([*args, "--out", str(out), "--json", "--quiet", "--report", str(tmp_path / "r")])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["extensions"]["chosen"] == []
    assert 0.95 <= doc["coverage"] <= 1.0
    cfg = load_config(out)
    assert cfg.disturbance is not None
    assert cfg.disturbance.input_max == pytest.approx(doc["disturbance"]["input_max"])
    assert cfg.disturbance.rate_max == pytest.approx(doc["disturbance"]["rate_max"])
    text = out.read_text()
    assert "# [identification] model extensions chosen: none" in text
    report = (tmp_path / "r" / "report.md").read_text()
    assert "Model extensions" in report and "Coverage on the validation record(s)" in report


def test_coverage_below_target_is_measured_and_said():
    # the validation record drifts 1.5 um over 3 s, the training record does not: the
    # bound sized on training alone cannot cover it, and the fit says so
    from bwdesign.identify import IdentificationData as Data

    valid = _record(2, 3.0)
    y = valid.y + 0.5 * (valid.t - valid.t[0])
    res = identify(_record(1, 4.0), validation=Data.from_arrays(valid.t, valid.u, y, source="v"))
    assert res.coverage < 0.95
    assert res.unexplained["band"]["coverage_full_bound"] >= 0.95
    note = [n for n in res.diagnostics if "held-out coverage" in n]
    assert len(note) == 1 and f"{100 * res.coverage:.2f} %" in note[0]
    # a record that is covered gets no such note
    ok = identify(_record(1, 4.0), validation=_record(2, 3.0))
    assert ok.coverage >= 0.95 and not any("held-out coverage" in n for n in ok.diagnostics)


def _bench_sine_and_holds(seed: int, kind: str, seconds: float = 20.0, fs: float = 200.0):
    """A 200 Hz record of a stage with a 2 ms amplifier lag and creep at 0.3 s and 3 s
    (not the bank's time constants), offset, drift, 16-bit: a 1 Hz sine, or a ramp
    with a hold and minor loops (where creep shows)."""
    t = np.arange(int(seconds * fs)) / fs
    if kind == "sine":
        u = 15 + 15 * np.sin(2 * np.pi * t - 0.7)
    else:
        env = np.clip(t / (seconds / 2), 0, 1)
        u = 15 + 15 * env * np.sin(2 * np.pi * 0.5 * t) + 2 * np.sin(2 * np.pi * 5 * t) * (t > 14)
        hold = (t > 6) & (t < 10)
        u[hold] = u[np.flatnonzero(hold)[0]]
    v = first_order_lag(u, 1 / fs, 2e-3)
    x = simulate_zoh(PLANT, v, 1 / fs, np.zeros(3), u_prev=v[0])[1:, 0]
    for tau, w in ((0.3, 0.04), (3.0, 0.03)):
        x = x + w * PLANT.static_gain * (first_order_lag(v, 1 / fs, tau) - v)
    rng = np.random.default_rng(seed)
    y = x + 5 + 0.02 * t / t[-1] + 0.005 * rng.standard_normal(t.size)
    q = 1.2 * np.ptp(y) / 2**16
    return IdentificationData.from_arrays(t, u, np.round(y / q) * q, source=kind)


def test_creep_reserve_is_the_banks_worst_case_less_what_was_seen():
    from bwdesign.identify.unexplained import creep_reserve

    rec = _bench_sine_and_holds(1, "sine", seconds=4.0)
    doc = {"candidates": {"creep": {"taus_s": [0.1, 1.0], "weights": [0.05, -0.02]}}}
    got = creep_reserve(doc, [rec], 0)
    u_range = float(np.ptp(rec.u))
    assert got["worst"] == pytest.approx(0.07 * u_range)
    c = 0.05 * (first_order_lag(rec.u, rec.dt, 0.1) - rec.u)
    c -= 0.02 * (first_order_lag(rec.u, rec.dt, 1.0) - rec.u)
    assert got["seen"] == pytest.approx(np.max(np.abs(c)))
    assert got["input"] == pytest.approx(got["worst"] - got["seen"])
    assert got["rate"] > 0
    # no creep fitted: no reserve
    assert creep_reserve({"candidates": {"creep": {"chosen": False}}}, [rec], 0)["input"] == 0


@pytest.mark.slow
def test_creep_a_sine_hides_is_in_the_bound():
    # a 1 Hz sine shows part of the creep, the held-out record's hold all of it: the
    # bound carries the creep the fitted weights could add at another input, so the
    # band covers the held-out record (it did not: 0.86 on a 40 s version)
    res = identify(_bench_sine_and_holds(1, "sine"), validation=_bench_sine_and_holds(2, "ramp"))
    assert res.converged
    reserve = res.unexplained["creep_reserve"]
    assert reserve["input"] > 0 and reserve["worst"] > reserve["seen"]
    assert res.coverage >= 0.95
    # the reserve is the bank's worst case, not a blanket: within 3x of the truth's creep
    truth_worst = (0.04 + 0.03) * PLANT.static_gain * 30.0
    assert reserve["worst"] < 3 * truth_worst
