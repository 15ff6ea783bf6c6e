"""The structural Bouc-Wen form: stage files, boundedness, simulation accuracy, validation and
identification on records generated from the hysteretic benchmark's published parameters."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bwdesign import preset
from bwdesign.cli.main import main
from bwdesign.errors import ConfigError, InputError, ParameterError, UnboundedModelError
from bwdesign.identify.hysteretic_benchmark import benchmark_records
from bwdesign.identify.structural import DETERMINED, identify_structural
from bwdesign.model.config import load_config, parse_config
from bwdesign.model.structural import BENCHMARK, StructuralParams
from bwdesign.model.structural_sim import (
    band_limited,
    simulate_batch,
    simulate_structural,
    steady_state,
)
from bwdesign.observers.structural import StructuralObserver, structural_gains

TRUE = {
    "m": 2.0,
    "c": 10.0,
    "k": 5e4,
    "alpha": 5e4,
    "beta_gamma": 1e3 * 0.8,
    "beta_delta": 1e3 * -1.1,
}

STAGE = """[plant]
form = "structural"
name = "bench"
m = 2.0
c = 10.0
k = 5e4
alpha = 5e4
beta = 1e3
gamma = 0.8
delta = -1.1
nu = 1
"""


def _write(tmp_path, text, name="stage.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _analytic_multisine(n: int, fs: float, seed: int, rms: float):
    """An exact multisine: its samples and its value at any time (the reference's input)."""
    rng = np.random.default_rng(seed)
    f = np.arange(n // 2 + 1) * fs / n
    lines = f[(f >= 5) & (f <= 150)]
    w, ph = 2 * np.pi * lines, 2 * np.pi * rng.random(lines.size)
    t = np.arange(n) / fs
    raw = np.cos(np.outer(t, w) + ph).sum(axis=1)
    scale = rms / np.sqrt(np.mean(raw**2))
    return raw * scale, lambda tt: scale * np.cos(w * tt + ph).sum()


def _reference(p: StructuralParams, u_of, t_end: float, t_eval, x0=(0.0, 0.0, 0.0)):
    """scipy DOP853 on the plain (y, y', z) equations at rtol 1e-13 (with the |.| kinks)."""

    def rhs(t, x):
        y, v, z = x
        zn = abs(z) ** (p.nu - 1.0)
        return [
            v,
            (u_of(t) - p.c * v - p.k * y - z) / p.m,
            p.alpha * v - p.beta * (p.gamma * abs(v) * zn * z + p.delta * v * zn * abs(z)),
        ]

    sol = solve_ivp(
        rhs, (0.0, t_end), list(x0), method="DOP853", rtol=1e-13,
        atol=[1e-17, 1e-15, 1e-12], t_eval=t_eval,
    )  # fmt: skip
    assert sol.success
    return sol.y


# -- the form in stage files ---------------------------------------------------------------------
def test_stage_file_round_trip(tmp_path):
    cfg = load_config(_write(tmp_path, STAGE), forms=("piezo", "structural"))
    assert cfg.plant == BENCHMARK.replace(name="bench")
    again = load_config(_write(tmp_path, cfg.plant.to_toml(), "b.toml"), forms=("structural",))
    assert again.plant == cfg.plant
    assert cfg.plant.units["beta"] == "1/m" and cfg.plant.units["k"] == "N/m"


@pytest.mark.parametrize(
    "change, error, words",
    [
        ({"nu": 0.5}, ParameterError, "nu"),
        ({"alpha": 0.0}, ParameterError, "alpha"),
        ({"m": -1.0}, ParameterError, "m"),
        ({"c": float("nan")}, ParameterError, "c"),
    ],
)
def test_bad_parameters_are_refused(change, error, words):
    data = {**BENCHMARK.to_dict(), **change}
    with pytest.raises(error, match=words):
        StructuralParams.from_dict(data)


def test_unknown_keys_form_and_sections_are_refused():
    with pytest.raises(ParameterError, match="unknown key"):
        StructuralParams.from_dict({**BENCHMARK.to_dict(), "a1": 1.0})
    with pytest.raises(ParameterError, match="missing field"):
        StructuralParams.from_dict({"form": "structural", "m": 1.0})
    with pytest.raises(ConfigError, match="form must be one of"):
        parse_config({"plant": {"form": "magnetic"}})
    plant = {**BENCHMARK.to_dict()}
    with pytest.raises(ConfigError, match="observer"):
        parse_config({"plant": plant, "observer": {"gains": [1, 2, 3]}})


def test_boundedness_classes():
    inside = BENCHMARK.replace(delta=0.5)  # beta (gamma + delta) > 0, beta (gamma - delta) >= 0
    v = inside.bounded_class()
    assert v.bounded and v.z_max == pytest.approx(5e4 / (1e3 * 1.3))
    bench = BENCHMARK.bounded_class()  # beta (gamma + delta) = -300: no finite escape at nu = 1
    assert not bench.bounded and not bench.finite_escape and bench.growth == pytest.approx(1900)
    escape = BENCHMARK.replace(nu=2.0)
    assert escape.bounded_class().finite_escape
    with pytest.raises(UnboundedModelError, match="finite monotone stroke"):
        simulate_structural(escape, np.ones(10), 1e-3, method="dop853")


def test_bounded_class_holds_in_simulation():
    p = BENCHMARK.replace(delta=0.5)
    u = 400.0 * np.sin(2 * np.pi * 3.0 * np.arange(3000) / 750.0)  # large strokes
    run = simulate_structural(p, u, 1 / 750.0, upsample=4)
    assert np.max(np.abs(run.z)) <= p.bounded_class().z_max * (1 + 1e-9)


# -- every command supports the form or refuses it -------------------------------------------------
@pytest.mark.parametrize(
    "argv",
    [
        ["certify", "--plant", "{}"],
        ["synthesize", "--plant", "{}"],
        ["simulate", "--plant", "{}", "--duration", "0.1"],
        ["report", "--config", "{}", "--out", "{d}/r"],
        ["sweep", "--config", "{}", "--samples", "2", "--out", "{d}/s"],
        ["export-c", "--config", "{}", "--out", "{d}/c"],
        ["check", "{}"],
        ["excite", "--plant", "{}", "--umin", "0", "--umax", "1", "--udot-max", "10",
         "--duration", "1", "--dt", "0.001", "--out", "{d}/x.csv"],
    ],
)  # fmt: skip
def test_other_commands_refuse_the_form(tmp_path, capsys, argv):
    stage = _write(tmp_path, STAGE)
    args = [a.format(stage, d=tmp_path) for a in argv]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:")
    assert 'form = "structural"' in err[0]
    assert not list(tmp_path.glob("*/*")), "nothing written"


def test_params_prints_the_form(tmp_path, capsys):
    assert main(["params", "--plant", str(_write(tmp_path, STAGE)), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["plant"]["form"] == "structural" and doc["bounded_class"]["bounded"] is False


# -- simulation ------------------------------------------------------------------------------------
def test_band_limited_interpolation_is_exact_for_a_periodic_multisine():
    fs, n = 750.0, 256
    u, u_of = _analytic_multisine(n, fs, seed=3, rms=10.0)
    fine = band_limited(u, 8, periodic=True)
    t = np.arange(fine.size) / (8 * fs)
    exact = np.array([u_of(tt) for tt in t])
    assert np.max(np.abs(fine - exact)) <= 1e-11 * np.max(np.abs(exact))


def test_band_limited_interpolation_of_a_sweep_record():
    """Non-periodic: the line through the ends plus an odd reflection; a linear 18 to 52 Hz
    sweep at 750 Hz is matched within 1e-5 of its amplitude away from the ends (10 ms),
    1e-3 everywhere."""
    fs, n = 750.0, 2048
    dur = n / fs

    def sweep(t):
        return 40.0 * np.sin(2 * np.pi * (18.0 * t + 0.5 * (52.0 - 18.0) / dur * t**2))

    fine = band_limited(sweep(np.arange(n) / fs), 8, periodic=False)
    err = np.abs(fine - sweep(np.arange(fine.size) / (8 * fs)))
    assert err.max() <= 1e-3 * 40.0
    assert err[60:-60].max() <= 1e-5 * 40.0


@pytest.fixture(scope="module")
def short_reference():
    fs, n = 750.0, 512
    u, u_of = _analytic_multisine(n, fs, seed=1, rms=50.0)
    t = np.arange(n) / fs
    return u, _reference(BENCHMARK, u_of, t[-1], t), fs


def test_fast_path_agrees_with_the_reference(short_reference):
    u, ref, fs = short_reference
    scale = np.max(np.abs(ref[0]))
    run = simulate_structural(BENCHMARK, u, 1 / fs, periodic=True, upsample=64)
    assert np.max(np.abs(run.y - ref[0])) <= 1e-9 * scale
    assert np.max(np.abs(run.z - ref[2])) <= 1e-9 * np.max(np.abs(ref[2]))
    # fourth order: doubling the steps divides the error by about 16
    e8 = np.max(
        np.abs(simulate_structural(BENCHMARK, u, 1 / fs, periodic=True, upsample=8).y - ref[0])
    )
    e16 = np.max(
        np.abs(simulate_structural(BENCHMARK, u, 1 / fs, periodic=True, upsample=16).y - ref[0])
    )
    assert 10.0 < e8 / e16 < 25.0


def test_the_compiled_integrator_is_the_python_one_to_the_bit():
    """structural_sim.rk4_compiled (numba) against _rk4_nu1 (Python): the benchmark's
    records from rest and from a moving state, and random inputs, steps and stiffness
    (reversals and zero crossings in most steps, or a divergence, whose message is the
    same); every float equal."""
    from bwdesign.errors import SolverError
    from bwdesign.model import structural_sim as S

    def both(p, fine, h, sps, total, x0):
        out = []
        for run in (S._rk4_nu1, S.rk4_compiled):
            try:
                out.append(run(p, fine.tolist() if run is S._rk4_nu1 else fine, h, sps, total, x0))
            except SolverError as err:
                out.append(str(err))
        return out

    rec = benchmark_records(seed=3)["train"]
    for periodic, x0 in [(True, (0.0, 0.0, 0.0)), (False, (1e-4, -2e-3, 3.0))]:
        fine = S._fine(rec.u[:1500], 4, periodic)
        a, b = both(BENCHMARK, fine, rec.dt / 4, 4, S._steps(rec.u[:1500], 4, periodic), x0)
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    rng = np.random.default_rng(1)
    kinds = set()
    for _ in range(30):
        p = BENCHMARK.replace(k=BENCHMARK.k * 10.0 ** rng.uniform(-1, 1))
        fine = 10.0 ** rng.uniform(0, 8) * rng.standard_normal(401)
        a, b = both(p, fine, 10.0 ** rng.uniform(-5, -1), 1, 200, (0.0, 0.0, 0.0))
        if isinstance(a, str):
            assert a == b and "diverged" in a
            kinds.add("error")
        else:
            assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
            kinds.add("ok")
    assert kinds == {"ok", "error"}


def test_error_control_meets_its_tolerance(short_reference):
    u, ref, fs = short_reference
    scale = np.max(np.abs(ref[0]))
    run = simulate_structural(BENCHMARK, u, 1 / fs, periodic=True, upsample=4, rtol=1e-10)
    assert run.error_estimate <= 1e-10 * scale * 1.01
    assert np.max(np.abs(run.y - ref[0])) <= 1e-9 * scale


def test_dop853_path_for_nu_above_one():
    p = BENCHMARK.replace(delta=0.5, nu=1.5, beta=40.0)
    fs, n = 750.0, 200
    u, u_of = _analytic_multisine(n, fs, seed=2, rms=50.0)
    t = np.arange(n) / fs
    ref = _reference(p, u_of, t[-1], t)
    run = simulate_structural(p, u, 1 / fs, periodic=True, method="dop853", rtol=1e-13)
    assert np.max(np.abs(run.y - ref[0])) <= 1e-9 * np.max(np.abs(ref[0]))


def test_steady_state_is_periodic_and_batch_matches():
    fs, n = 750.0, 1024
    u, _ = _analytic_multisine(n, fs, seed=4, rms=50.0)
    ss = steady_state(BENCHMARK, u, 1 / fs, upsample=4, tol=1e-10)
    again = simulate_structural(
        BENCHMARK, u, 1 / fs, periodic=True, upsample=4, x0=(ss.y[0], ss.v[0], ss.z[0])
    )
    assert np.max(np.abs(again.y - ss.y)) <= 1e-9 * np.max(np.abs(ss.y))
    other = BENCHMARK.replace(c=20.0)
    batch = simulate_batch([BENCHMARK, other], u, 1 / fs, steady=True, upsample=4, tol=1e-10)
    assert np.array_equal(batch[0], ss.y)
    assert np.array_equal(batch[1], steady_state(other, u, 1 / fs, upsample=4, tol=1e-10).y)


# -- the benchmark: records, validate, identify --------------------------------------------
@pytest.fixture(scope="module")
def records(tmp_path_factory):
    recs = benchmark_records(seed=0)
    d = tmp_path_factory.mktemp("records")
    paths = {}
    for key, rec in recs.items():
        paths[key] = d / f"{key}.csv"
        np.savetxt(paths[key], np.c_[rec.t, rec.u, rec.y], delimiter=",", header="t,u,y",
                   comments="", fmt="%.17g")  # fmt: skip
    return recs, paths


def test_validate_scores_the_true_stage(records, tmp_path, capsys):
    _, paths = records
    stage = _write(tmp_path, STAGE)
    argv = ["validate", "--plant", str(stage), "--data", str(paths["valid_multisine"])]
    assert main([*argv, "--periodic", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["form"] == "structural" and doc["unit"] == "m"
    assert doc["rms_error"] < 1e-9 and doc["fit_percent"] > 99.9999
    assert main(argv + ["--json"]) == 0  # not periodic: from rest, the transient is an error
    assert json.loads(capsys.readouterr().out)["rms_error"] > 1e-7
    assert main(["validate", "--plant", str(stage), "--data", str(paths["train"]), "--periodic",
                 "--json"]) == 0  # fmt: skip
    noise = json.loads(capsys.readouterr().out)["rms_error"]
    assert noise == pytest.approx(8e-6, rel=0.05)  # the training record's noise


def test_validate_takes_the_piezo_form(capsys):
    argv = ["validate", "--plant", "paper_experiment", "--data"]
    assert main([*argv, "examples/identification/valid.csv", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["form"] == "piezo" and 0 < doc["fit_percent"] <= 100


@pytest.fixture(scope="module")
def fitted(records, tmp_path_factory):
    """``bwdesign identify --form structural --periodic --json`` on the training record."""
    recs, paths = records
    out = tmp_path_factory.mktemp("fit")
    argv = [
        "identify", "--form", "structural", "--periodic", "--data", str(paths["train"]),
        "--validate", str(paths["valid_multisine"]), "--out", str(out / "stage.toml"),
        "--report", str(out / "report"), "--json", "--quiet",
    ]  # fmt: skip
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    return code, buf.getvalue(), out


def test_identify_from_the_benchmark_record(fitted):
    code, text, out = fitted
    assert code == 0
    doc = json.loads(text)
    for name in DETERMINED:
        lo, hi = doc["determined"][name]["ci95"]
        assert lo <= TRUE[name] <= hi, name
        assert hi - lo < 0.05 * abs(TRUE[name]), name  # determined, not a vacuous interval
    assert doc["not_determined"]["parameters"] == ["beta", "gamma", "delta"]
    assert doc["residual_rms_validation"] <= 1e-6
    assert doc["residual_rms"] == pytest.approx(8e-6, rel=0.05)
    assert (out / "report" / "report.md").exists()
    assert "beta = 1 below is a convention" in (out / "stage.toml").read_text()


def test_the_identified_stage_validates_on_the_sweep(fitted, records, capsys):
    code, _, out = fitted
    _, paths = records
    assert code == 0
    stage = str(out / "stage.toml")
    assert main(["validate", "--plant", stage, "--data", str(paths["valid_sweep"]), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rms_error"] <= 1e-6


def test_identification_is_scale_free_at_nu_one(records):
    """beta*gamma and beta*delta are what is reported: rescaling beta by 10 and gamma,
    delta by 1/10 gives the same output, so no record can tell them apart."""
    recs, _ = records
    other = BENCHMARK.replace(beta=1e4, gamma=0.08, delta=-0.11)
    rec = recs["valid_multisine"]
    a = steady_state(BENCHMARK, rec.u, rec.dt, upsample=4).y
    b = steady_state(other, rec.u, rec.dt, upsample=4).y
    assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(a))


def test_identify_refuses_piezo_options(tmp_path, capsys, records):
    _, paths = records
    base = ["identify", "--data", str(paths["train"]), "--out", str(tmp_path / "s.toml")]
    assert main([*base, "--form", "structural", "--init", "paper_experiment"]) == 2
    assert main([*base, "--periodic"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith("error:") for e in err)
    assert not (tmp_path / "s.toml").exists()


@pytest.mark.slow
def test_identify_structural_without_validation_nonperiodic(records):
    """A non-periodic record from rest (the sweep) also identifies the six coordinates."""
    recs, _ = records
    fit = identify_structural([recs["valid_sweep"]], periodic=False)
    assert fit.converged
    for name in DETERMINED:
        assert fit.values[name] == pytest.approx(TRUE[name], rel=1e-3), name


# -- the observer (no certificate) ---------------------------------------------------------------
def test_observer_poles_are_where_asked():
    from bwdesign.observers.structural import _linear_model

    dt = 1 / 750.0
    K = structural_gains(BENCHMARK, dt, 20.0)
    f = _linear_model(BENCHMARK, dt)
    eig = np.sort(np.abs(np.linalg.eigvals((np.eye(3) - np.outer(K, [1.0, 0, 0])) @ f)))
    r = np.exp(-2 * np.pi * 20.0 * dt)
    assert np.allclose(eig, np.sort([r, 0.9 * r, 0.8 * r]), rtol=1e-9)


def test_observer_tracks_z_from_a_wrong_start(records):
    recs, _ = records
    for key, bound in (("valid_multisine", 1e-3), ("train", 2e-2)):  # noise free, 8e-6 m noise
        rec = recs[key]
        truth = steady_state(BENCHMARK, rec.u, rec.dt, upsample=16)
        obs = StructuralObserver(BENCHMARK, rec.dt)
        obs.reset([1e-3, 0.0, 0.0])
        xs = obs.batch_filter(rec.y, rec.u)
        assert abs(xs[0, 2] - truth.z[0]) > 10.0  # it starts wrong
        tail = slice(2000, None)
        err = np.sqrt(np.mean((xs[tail, 2] - truth.z[tail]) ** 2))
        assert err <= bound * np.sqrt(np.mean(truth.z**2)), key


def test_observer_refuses_bad_input():
    with pytest.raises(InputError, match="StructuralParams"):
        StructuralObserver(preset("paper_experiment"), 1e-3)
    obs = StructuralObserver(BENCHMARK, 1 / 750.0)
    with pytest.raises(InputError):
        obs.predict(float("nan"))
    obs.predict(1.0)
    before = obs.x.copy()
    obs.update(None)  # a missing sample: no correction
    assert np.array_equal(obs.x, before)


@pytest.mark.slow
def test_identify_a_saturated_class_one_record():
    """A class-I stage driven deep into saturation (z_max = 4.4 N under a 30 N RMS input):
    the linear part sees mostly k, and the first version of the fit stopped at its start."""
    from bwdesign.identify.data import IdentificationData
    from bwdesign.identify.hysteretic_benchmark import multisine

    p = StructuralParams(m=1.0, c=20.0, k=2e3, alpha=8e3, beta=2e3, gamma=0.6, delta=0.3)
    fs, n = 500.0, 4096
    u = multisine(n, fs, (1.0, 60.0), 30.0, 5)
    y = steady_state(p, u, 1 / fs, upsample=32).y
    y = y + 1e-5 * np.random.default_rng(9).standard_normal(n)
    rec = IdentificationData.from_arrays(np.arange(n) / fs, u, y, source="class I")
    fit = identify_structural([rec], periodic=True)
    assert fit.converged
    true = {"m": 1.0, "c": 20.0, "k": 2e3, "alpha": 8e3, "beta_gamma": 1200.0, "beta_delta": 600.0}
    for name in DETERMINED:
        lo, hi = fit.ci95[name]
        assert lo <= true[name] <= hi, name
