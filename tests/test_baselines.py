"""Baseline controllers (issue 29): PI/PID on the measurement, the hysteresis feedforwards,
the tuning rule, anti-windup, the Prandtl–Ishlinskii operator and its fit."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bwdesign import (
    BaselineController,
    ClosedLoop,
    InputError,
    ObserverSpec,
    PrandtlIshlinskii,
    Sine,
    Triangle,
    UncertaintyBox,
    analyze_baseline,
    analyze_loop,
    fit_prandtl_ishlinskii,
    load_config,
    make_controller,
    preset,
    simulate,
    simulate_batch,
    simulate_continuous,
    tune_baseline,
)
from bwdesign.cli.main import main
from bwdesign.control.baseline_tuning import sampled_plant
from bwdesign.control.baselines import PIDState, pid_step
from bwdesign.errors import GainError, ParameterError
from bwdesign.identify.prandtl import model_record
from bwdesign.study.baselines import DEFAULT_BOX

PAPER_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "paper_experiment.toml"

DT = 2e-4


@pytest.fixture(scope="module")
def config():
    return load_config(PAPER_CONFIG)


@pytest.mark.parametrize("kind", ["pi", "pid"])
@pytest.mark.parametrize("delay", [False, True])
@pytest.mark.parametrize("pm", [45.0, 60.0])
def test_tuning_rule_gives_the_stated_phase_margin(kind, delay, pm):
    p = preset("paper_experiment")
    c = tune_baseline(p, DT, kind=kind, phase_margin=pm, delay=delay)
    wc = c.tuning["crossover_rad_s"]
    # the loop at the crossover, evaluated directly: |L| = 1, arg L = -180 + pm
    z = np.exp(1j * wc * DT)
    cnum, cden = c.transfer()
    pnum, pden = sampled_plant(p, DT, slope=p.alpha, delay=delay)
    L = np.polyval(cnum, z) / np.polyval(cden, z) * np.polyval(pnum, z) / np.polyval(pden, z)
    assert abs(abs(L) - 1.0) < 1e-9
    assert math.degrees(np.angle(L)) + 180.0 == pytest.approx(pm, abs=1e-6)
    a = analyze_baseline(c, p, delay=delay)
    assert a.stable and a.spectral_radius < 1.0
    assert a.phase_margin == pytest.approx(pm, abs=0.05)
    assert a.crossover == pytest.approx(wc, rel=1e-3)
    assert a.gain_margin is not None and a.gain_margin > 2.0  # > 6 dB on this stage
    assert "not stable" not in a.describe()


def test_destabilising_gains_are_not_stable_with_their_margins():
    p = preset("paper_experiment")
    c = BaselineController(60.0, 2e4, dt=DT)
    a = analyze_baseline(c, p)
    assert not a.stable and a.worst_radius > 1.0
    text = a.describe()
    assert text.startswith("not stable") and "phase margin" in text and "gain margin" in text
    assert a.gain_margin is not None and a.gain_margin < 1.0


def test_anti_windup_holds_the_integrator_in_saturation():
    c = BaselineController(1.0, 100.0, dt=DT, u_limits=(0.0, 10.0)).constants()
    s = PIDState(0.05, 0.0, 0.0)
    clip = lambda v, lo, hi: min(max(v, lo), hi)  # noqa: E731
    for _ in range(10_000):  # a large positive error: saturated high all along
        u = pid_step(c, s, 0.0, 50.0, 0.0, clip)
        assert u == 10.0
    assert s.q == 0.05  # frozen, not 10000 * dt * 50 = 100
    u = pid_step(c, s, 52.0, 50.0, 0.0, clip)  # the error changes sign: integrates again
    assert s.q == pytest.approx(0.05 - DT * 2.0)
    assert u == pytest.approx(-2.0 + 100.0 * (0.05 - DT * 2.0))  # inside the limits
    for _ in range(100):  # a large negative error: saturated low, held again
        assert pid_step(c, s, 100.0, 50.0, 0.0, clip) == 0.0
    assert s.q == pytest.approx(0.05 - DT * 2.0)


def test_anti_windup_loop_recovers_after_saturation(config):
    """A limit below what the reference needs at its top: saturated part of the period,
    bounded, and back on the reference soon after."""
    lo, hi = 0.0, 120.0  # the 1 Hz sine needs up to about 130 V at its top
    loop = ClosedLoop.baseline_from_config(config, "pi-bwff").replace(
        controller=tune_baseline(config.plant, DT, u_limits=(lo, hi))
    )
    r = simulate(loop, config.reference, duration=3.0)
    assert r.stable
    assert 0.0 < r.saturated_fraction < 0.3
    at_limit = (r.u >= hi) | (r.u <= lo)
    free = ~at_limit & (r.t > 1.0)
    # away from the limit (and 50 ms after leaving it) the PI tracks to well under 5 um
    last = np.maximum.accumulate(np.where(at_limit, r.t, -np.inf))
    settled = free & (r.t - last > 0.05)
    assert settled.any() and np.max(np.abs(r.e[settled])) < 5.0


def test_prandtl_inverse_composes_to_identity():
    rng = np.random.default_rng(3)
    op = PrandtlIshlinskii((0.0, 0.7, 1.5, 2.4, 4.0), tuple(rng.uniform(0.05, 1.0, 5)), offset=-2.5)
    t = np.linspace(0, 4, 3001)
    u = 6 * np.sin(2 * np.pi * t) * (1 - 0.2 * t) + rng.normal(0, 0.3, t.size) + 1.0
    y = op(u)
    inv = op.inverse()
    assert np.max(np.abs(inv(y) - u)) < 1e-9
    assert np.max(np.abs(op(inv(y)) - y)) < 1e-9


def test_prandtl_fit_recovers_known_weights():
    t = np.arange(3000) * 1e-3
    u = 40 + 30 * np.sin(2 * np.pi * 0.5 * t) * (1 - 0.25 * t)
    n = 8
    half = 0.5 * float(np.ptp(u))
    weights = (0.9, 0.3, 0.0, 0.15, 0.2, 0.0, 0.05, 0.1)
    true = PrandtlIshlinskii(tuple(i * half / n for i in range(n)), weights, offset=3.0)
    fit = fit_prandtl_ishlinskii((t, u, true(u)), n_operators=n)
    assert np.allclose(fit.operator.weights, weights, atol=1e-8)
    assert fit.operator.offset == pytest.approx(3.0, abs=1e-7)
    assert fit.rmse < 1e-8


def test_prandtl_fit_refuses_bad_records():
    t = np.arange(1000) * 1e-3
    u = 10 * np.sin(2 * np.pi * t)
    op = PrandtlIshlinskii((0.0, 1.0, 2.0), (1.0, 0.5, 0.2))
    with pytest.raises(InputError, match="does not rise with the input"):
        fit_prandtl_ishlinskii((t, u, -op(u)))  # non-monotone: the output falls as u rises
    t_bad = t.copy()
    t_bad[500] = t_bad[499]
    with pytest.raises(InputError, match="not increasing"):
        fit_prandtl_ishlinskii((t_bad, u, op(u)))
    with pytest.raises(InputError, match="NaN"):
        fit_prandtl_ishlinskii((t, np.where(t > 0.5, np.nan, u), op(u)))
    with pytest.raises(InputError):
        fit_prandtl_ishlinskii((t, u, op(u)), n_operators=1)


def test_prandtl_operator_refuses_bad_parameters():
    with pytest.raises(ParameterError, match="not invertible"):
        PrandtlIshlinskii((0.0, 1.0), (1.0, -1.5)).inverse()
    with pytest.raises(ParameterError, match="start at 0"):
        PrandtlIshlinskii((0.5, 1.0), (1.0, 1.0))
    with pytest.raises(ParameterError, match="differ in length"):
        PrandtlIshlinskii((0.0, 1.0), (1.0,))


def test_prandtl_fit_of_the_model_is_close():
    p = preset("paper_experiment")
    fit = fit_prandtl_ishlinskii(model_record(p, (20.0, 180.0)))
    assert fit.operator.invertible()
    assert fit.rmse < 0.01 * fit.range  # within 1 % of the range on the Bouc-Wen loops


def test_bad_gains_and_inconsistent_loops(config):
    with pytest.raises(GainError):
        BaselineController(-1.0, 1.0, dt=DT)
    with pytest.raises(GainError):
        BaselineController(1.0, 0.0, dt=DT)
    with pytest.raises(GainError, match="tf"):
        BaselineController(1.0, 1.0, kd=1e-3, dt=DT)
    with pytest.raises(GainError, match="kp, ki, kd, tf"):
        ClosedLoop.baseline_from_config(config, "pid", gains=(1.0, 2.0))
    p = config.plant
    base = ClosedLoop.baseline_from_config(config, "pi")
    assert base.baseline and base.observer is None
    with pytest.raises(InputError, match="without an observer"):
        base.replace(observer=ObserverSpec.of("phso", (8.0, 64.0, -512.0)))
    with pytest.raises(InputError, match="built for dt"):
        base.replace(controller=tune_baseline(p, 1e-4))
    with pytest.raises(InputError, match="needs an observer"):
        ClosedLoop(p, None, make_controller(p, 1.0, 2.0), dt=DT)
    with pytest.raises(InputError, match="no observer"):
        analyze_loop(base)
    with pytest.raises(InputError, match="no observer"):
        simulate_continuous(base, config.reference, duration=0.1)
    with pytest.raises(InputError, match="baseline kind"):
        ClosedLoop.baseline_from_config(config, "pi-xyz")


def test_inverse_bouc_wen_feedforward_is_exact_on_the_model(config):
    r = simulate(ClosedLoop.baseline_from_config(config, "pi-bwff"), config.reference, duration=3)
    assert r.stable and r.metrics.me < 1e-6 and r.estimation_rmse is None
    assert np.isnan(r.xhat).all()


@pytest.mark.parametrize("kind", ["pi", "pid", "pi-bwff", "pi-piff"])
def test_batch_agrees_with_simulate(config, kind):
    p = config.plant
    plants = [p, dataclasses.replace(p, a1=1.02 * p.a1, alpha=0.9 * p.alpha)]
    ref = Sine(amplitude=80.0, offset=100.0, frequency=5.0)
    loop = ClosedLoop.baseline_from_config(config, kind, delay=True)
    b = simulate_batch(loop, ref, plants, duration=0.6, noise_std=[0.0, 0.02], seeds=[0, 4])
    for i, tp in enumerate(plants):
        r = simulate(loop, ref, duration=0.6, true_params=tp, noise_std=[0.0, 0.02][i], seed=4 * i)
        assert b.stable[i] and r.stable
        for name in ("me", "maxe", "rmse"):  # to the bit (sim/zoh.py, sim/compiled.py)
            assert getattr(b, name)[i] == getattr(r.metrics, name)
        assert b.saturated_fraction[i] == r.saturated_fraction
        assert np.isnan(b.estimation_rmse[i]).all()


# -- the command line ------------------------------------------------------------------

CLI = ["simulate", "--plant", str(PAPER_CONFIG), "--start-on-reference"]


@pytest.mark.parametrize("kind", ["pi", "pid", "pi-bwff", "pi-piff"])
def test_cli_simulate_runs_each_baseline(kind, capsys, config):
    assert main([*CLI, "--controller", kind, "--duration", "3", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["controller"] == kind and doc["observer"] is None
    assert doc["estimation_rmse"] is None and doc["nominal_loop"]["stable"]
    assert doc["nominal_loop"]["phase_margin_deg"] == pytest.approx(60.0, abs=0.05)
    # the same numbers as the Python API on the same loop
    r = simulate(ClosedLoop.baseline_from_config(config, kind), config.reference, duration=3.0)
    assert doc["metrics"]["me"] == r.metrics.me and doc["metrics"]["maxe"] == r.metrics.maxe


def test_cli_mismatch_reproduces_a_box_corner(capsys, config):
    box = UncertaintyBox.from_dict({"a1": {"rel": 0.02}, "alpha": {"rel": 0.1}})
    corner = box.vertices(config.plant)[1]  # a1 low, alpha high
    assert main([*CLI, "--controller", "pi", "--duration", "3", "--json",
                 "--mismatch", "a1=-2.0%,alpha=+10.0%"]) == 0  # fmt: skip
    doc = json.loads(capsys.readouterr().out)
    r = simulate(
        ClosedLoop.baseline_from_config(config, "pi"),
        config.reference,
        duration=3.0,
        true_params=corner,
    )
    assert doc["settings"]["true_plant"]["a1"] == corner.a1
    assert doc["settings"]["true_plant"]["alpha"] == corner.alpha
    assert doc["metrics"]["me"] == r.metrics.me


def test_cli_destabilising_gains_say_not_stable_with_margins(capsys):
    code = main([*CLI, "--controller", "pid", "--kp", "60", "--ki", "20000", "--kd", "0.001",
                 "--tf", "1e-4", "--duration", "0.5"])  # fmt: skip
    out = capsys.readouterr().out
    assert code == 1
    assert "nominal linear loop: not stable: phase margin" in out and "gain margin" in out


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--controller", "pi", "--gains", "1,2,3"], "has no observer"),
        (["--controller", "pi", "--observer", "eso"], "has no observer"),
        (["--controller", "pi", "--kp", "1"], "needs --kp, --ki"),
        (["--controller", "pid", "--kp", "1", "--ki", "2"], "--kd, --tf"),
        (["--controller", "pi", "--kp", "1", "--ki", "2", "--phase-margin", "50"], "not both"),
        (["--kp", "1"], "baseline --controller only"),
        (["--controller", "pi", "--phase-margin", "5"], "phase_margin"),
        (["--controller", "pi", "--mismatch", "a9=2%"], "--mismatch"),
        (["--controller", "pi", "--mismatch", "a1=2%", "--true-plant", "paper_experiment"],
         "not both"),
        (["--controller", "pi", "--kp", "-1", "--ki", "2"], "kp"),
    ],
)  # fmt: skip
def test_cli_baseline_bad_input(extra, message, capsys):
    assert main([*CLI, "--duration", "1", *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and message in err[0]


# -- the study's comparison and the check ------------------------------------------------


@pytest.fixture(scope="module")
def comparison(config):
    from bwdesign.design.tuning import digital_tuning
    from bwdesign.study.baselines import baseline_comparison

    ref = Sine(amplitude=80.0, offset=100.0, frequency=20.0)  # 0.15 s runs: cheap
    tuning = digital_tuning(config.plant, config.dt)
    return baseline_comparison(config, gains=config.gains, tuning=tuning, reference=ref)


def test_comparison_rows_and_winners(comparison):
    labels = [r.label for r in comparison.rows]
    assert labels[:4] == ["PI", "PID", "PI + inverse Bouc-Wen", "PI + Prandtl-Ishlinskii"]
    assert "PHDO (digital tuning)" in labels and len(labels) == 10
    assert comparison.box_source == "default" and comparison.corners == 64
    for where in ("nominal", "worst"):
        w = getattr(comparison, f"{where}_winner")
        stable = [getattr(r, where) for r in comparison.rows if getattr(r, where).stable]
        assert w.me == min(o.me for o in stable)
        other = [
            getattr(r, where).me
            for r in comparison.rows
            if r.baseline != w.baseline and getattr(r, where).stable
        ]
        assert w.factor == pytest.approx(min(other) / w.me)
    for r in comparison.rows:  # the worst corner is no better than the nominal plant
        if r.nominal.stable and r.worst.stable:
            assert r.worst.me >= r.nominal.me * (1 - 1e-12)


@pytest.mark.parametrize("label", ["PI + inverse Bouc-Wen", "PHDO (digital tuning)"])
def test_comparison_commands_reproduce_the_numbers(comparison, label, capsys):
    row = next(r for r in comparison.rows if r.label == label)
    for outcome in (row.nominal, row.worst):
        code = main([*outcome.command, "--json"])
        doc = json.loads(capsys.readouterr().out)
        assert code == 0
        assert doc["metrics"]["me"] == outcome.me and doc["metrics"]["maxe"] == outcome.maxe


def _stage(tmp_path, body: str):
    text = PAPER_CONFIG.read_text().split("[requirements]")[0]
    path = tmp_path / "stage.toml"
    path.write_text(text + body)
    return str(path)


def test_check_baseline_stable(tmp_path, capsys):
    bad = _stage(
        tmp_path,
        '[baseline]\nkind = "pid"\ngains = [60.0, 20000.0, 0.001, 0.0001]\n\n'
        "[requirements]\nbaseline_stable = true\n",
    )
    assert main(["check", bad, "--no-cache"]) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "baseline_stable" in out and "not stable: phase margin" in out
    good = _stage(
        tmp_path, '[baseline]\nkind = "pi-bwff"\n\n[requirements]\nbaseline_stable = true\n'
    )
    assert main(["check", good, "--no-cache"]) == 0
    assert "PASS" in capsys.readouterr().out
    missing = _stage(tmp_path, "[requirements]\nbaseline_stable = true\n")
    assert main(["check", missing, "--no-cache"]) == 2
    assert "[baseline]" in capsys.readouterr().err


@pytest.mark.parametrize(
    "body, message",
    [
        ('kind = "p"\n', "kind must be one of"),
        ('kind = "pid"\ngains = [1.0, 2.0]\n', "[kp, ki, kd, tf]"),
        ('kind = "pi"\ngains = [1.0, 2.0]\nphase_margin = 50.0\n', "not both"),
        ('kind = "pi"\nfoo = 1\n', "unknown key"),
    ],
)
def test_baseline_section_bad_input(tmp_path, body, message):
    from bwdesign.errors import ConfigError

    with pytest.raises(ConfigError, match=message):
        load_config(_stage(tmp_path, "[baseline]\n" + body))


def test_sweep_runs_baselines_as_rows(config):
    from bwdesign.design.tuning import digital_tuning
    from bwdesign.model.params import MODEL_FIELDS
    from bwdesign.sim.sweep import SweepSpec, draw_scenarios, run_sweep

    tune = digital_tuning(config.plant, config.dt)
    ref = Sine(amplitude=80.0, offset=100.0, frequency=20.0)
    spec = SweepSpec(
        loop=ClosedLoop.from_config(config, law=tune).replace(delay=False),
        reference=ref,
        duration=0.15,
        gains=tuple(tune.gains),
        observers=("phdo", "pi", "pi-piff"),
        box=DEFAULT_BOX,
    )
    sc = draw_scenarios(config.plant, DEFAULT_BOX, 5, seed=2)
    one = run_sweep(spec, sc, chunk_size=5, workers=0)
    many = run_sweep(spec, sc, chunk_size=2, workers=0)
    for k in ("me", "maxe", "rmse"):
        assert np.array_equal(one[k], many[k])
    rows = one["observer"] == "pi-piff"
    assert rows.sum() == 5 and np.isnan(one["est_rmse_x1"][rows]).all()
    i = int(np.flatnonzero(rows)[3])
    tp = dataclasses.replace(config.plant, **{k: float(one[k][i]) for k in MODEL_FIELDS})
    loop = ClosedLoop.baseline_from_config(config, "pi-piff").replace(start="reference")
    r = simulate(loop, ref, duration=0.15, true_params=tp)
    assert one["me"][i] == pytest.approx(r.metrics.me, rel=1e-9)
    with pytest.raises(InputError, match="sweep observers"):
        SweepSpec(loop=spec.loop, reference=ref, duration=0.15, gains=spec.gains, observers=("p",))


def test_sweep_section_accepts_baselines(tmp_path):
    cfg = load_config(_stage(tmp_path, '[sweep]\nsamples = 3\nobservers = ["phso", "pi-bwff"]\n'))
    assert cfg.sweep["observers"] == ("phso", "pi-bwff")


# -- export-c ------------------------------------------------------------------------------

CC = shutil.which("cc") or shutil.which("gcc")
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wdouble-promotion",
          "-Werror", "-O2"]  # fmt: skip
needs_cc = pytest.mark.skipif(
    CC is None and not os.environ.get("BWDESIGN_REQUIRE_CC"), reason="no C compiler"
)


def _harness_input(result, reference, dt: float) -> str:
    xm, vm, am = (np.asarray(a, float).tolist() for a in reference.evaluate(result.t + dt / 2))
    rows = zip(result.z.tolist(), result.x_d.tolist(), xm, vm, am, strict=True)
    head = f"{result.settings['x0'][0]!r},{result.settings['u_prev']!r}"
    return "\n".join([head, *(",".join(map(repr, r)) for r in rows)]) + "\n"


@needs_cc
@pytest.mark.parametrize("kind", ["pi", "pid", "pi-piff"])
@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_exported_baseline_reproduces_the_python_loop(kind, precision, config, tmp_path):
    """The C law fed the simulated loop's measurements gives its inputs: float64 bit for bit,
    float32 within 2e-5 of the input range; with noise and the limits active (anti-windup)."""
    from bwdesign.codegen.baselines import export_baseline_c

    cfg = dataclasses.replace(
        config, controller=dataclasses.replace(config.controller, u_min=0.0, u_max=125.0)
    )
    out = tmp_path / "c"
    export_baseline_c(cfg, out, kind, precision=precision)
    exe = tmp_path / "harness"
    sources = sorted(str(p) for p in out.glob("*.c"))
    subprocess.run([CC, *STRICT, *sources, "-lm", "-o", str(exe)], check=True, capture_output=True)
    loop = ClosedLoop.baseline_from_config(cfg, kind)
    r = simulate(loop, cfg.reference, duration=3.0, noise_std=0.02, seed=3)
    assert 0.05 < r.saturated_fraction < 0.5  # the anti-windup is exercised
    res = subprocess.run(
        [str(exe)], input=_harness_input(r, cfg.reference, cfg.dt), capture_output=True,
        text=True, check=True,
    )  # fmt: skip
    u = np.array([float(v) for v in res.stdout.split()])
    if precision == "float64":
        assert np.array_equal(u, r.u)
    else:
        assert np.max(np.abs(u - r.u)) < 2e-5 * np.ptp(r.u)


@needs_cc
@pytest.mark.parametrize("shape", ["sine", "triangle"])
@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_exported_pi_bwff_reproduces_the_python_loop(shape, precision, config, tmp_path):
    """The exact inverse Bouc-Wen feedforward in C (the Newton iteration of
    bwdesign.model.inverse, libm's expm1/log1p) with the PI: float64 bit for bit, float32
    within 4e-6 of the input range (measured 9.4e-7 on the sine, 7.6e-7 on the triangle);
    noise and the limits active."""
    from bwdesign.codegen.baselines import export_baseline_c

    ref = config.reference if shape == "sine" else Triangle(amplitude=90.0, offset=100.0,
                                                             frequency=1.0)  # fmt: skip
    cfg = dataclasses.replace(
        config, reference=ref,
        controller=dataclasses.replace(config.controller, u_min=0.0, u_max=125.0),
    )  # fmt: skip
    out = tmp_path / "c"
    export_baseline_c(cfg, out, "pi-bwff", precision=precision)
    exe = tmp_path / "harness"
    sources = sorted(str(p) for p in out.glob("*.c"))
    subprocess.run([CC, *STRICT, *sources, "-lm", "-o", str(exe)], check=True, capture_output=True)
    r = simulate(ClosedLoop.baseline_from_config(cfg, "pi-bwff"), ref, duration=3.0,
                 noise_std=0.02, seed=3)  # fmt: skip
    assert 0.05 < r.saturated_fraction < 0.5  # the anti-windup is exercised
    res = subprocess.run(
        [str(exe)], input=_harness_input(r, ref, cfg.dt), capture_output=True, text=True,
        check=True,
    )  # fmt: skip
    u = np.array([float(v) for v in res.stdout.split()])
    if precision == "float64":
        assert np.array_equal(u, r.u)
    else:
        assert np.max(np.abs(u - r.u)) < 4e-6 * np.ptp(r.u)


def test_export_pi_bwff_and_bad_options(config, tmp_path, capsys):
    from bwdesign.codegen.baselines import export_baseline_c

    unbounded = dataclasses.replace(config, plant=preset("paper_simulation"))
    with pytest.raises(InputError, match="bounded Bouc-Wen class"):
        export_baseline_c(unbounded, tmp_path / "x", "pi-bwff", allow_unbounded=True)
    assert not (tmp_path / "x").exists()
    argv = ["export-c", "--config", str(PAPER_CONFIG), "--out", str(tmp_path / "w")]
    assert main([*argv, "--controller", "pi-bwff", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["controller"]["kind"] == "pi-bwff"
    assert doc["controller"]["feedforward"]["kind"] == "bwff"
    assert doc["inverse"]["tol"] == 1e-14 and doc["inverse"]["max_iter"] == 100
    assert sorted(doc["files"]) == ["bw.c", "bw.h", "export.json", "harness.c"]
    code = (tmp_path / "w" / "bw.c").read_text()
    p = config.plant
    assert f"A3 = {p.a3.hex()}" in code and f"GAMMA = {p.gamma.hex()}" in code
    assert "bw_ff_step" in code and "log1p(arg)" in code
    argv = ["export-c", "--config", str(PAPER_CONFIG), "--out", str(tmp_path / "y")]
    assert main([*argv, "--controller", "pi", "--tuning", "digital"]) == 2
    assert "drop --tuning" in capsys.readouterr().err
    assert main([*argv, "--controller", "pid", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["controller"]["kind"] == "pid" and doc["nominal_loop"]["stable"]
    assert sorted(doc["files"]) == ["bw.c", "bw.h", "export.json", "harness.c"]


def test_plugin_turns_baseline_stable_into_an_item(tmp_path):
    root = Path(__file__).resolve().parents[1]
    text = PAPER_CONFIG.read_text().split("[requirements]")[0]
    body = '[baseline]\nkind = "pid"\ngains = [60.0, 20000.0, 0.001, 0.0001]\n\n'
    (tmp_path / "stage.toml").write_text(text + body + "[requirements]\nbaseline_stable = true\n")
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", PYTHONPATH=str(root))
    res = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rf",
         "--bwdesign-configs", "stage.toml"],
        cwd=tmp_path, capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert res.returncode == 1, res.stdout + res.stderr
    assert re.search(r"\b1 failed\b", res.stdout)
    assert "the [baseline] controller's nominal loop is stable" in res.stdout
    assert "not stable: phase margin" in res.stdout
