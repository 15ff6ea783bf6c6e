"""C export: the generated code compiles cleanly and agrees with the Python classes."""

from __future__ import annotations

import ctypes
import json
import os
import re
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bwdesign import (
    ClosedLoop,
    DiscreteTrackingController,
    DisturbanceHysteresisObserver,
    ExtendedStateObserver,
    HysteresisObserver,
    ObserverSpec,
    TrackingController,
    load_config,
    simulate,
    simulate_zoh,
)
from bwdesign.cli.main import main
from bwdesign.codegen import c_literal, export_c
from bwdesign.errors import InternalError, NotCertifiedError
from bwdesign.model.references import Triangle
from bwdesign.observers.gains import disturbance_gains_from

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "paper_experiment.toml"
STACK = ROOT / "configs" / "stack_actuator_800hz.toml"
CC = shutil.which("cc") or shutil.which("gcc")
STRICT = [
    "-std=c99",
    "-Wall",
    "-Wextra",
    "-Wpedantic",
    "-Wconversion",
    "-Wdouble-promotion",
    "-Werror",
    "-O2",
]
#: the records' length in steps (0.2 ms each): every comparison runs on 2e4 steps (4 s: four
#: triangle periods with their minor loops, ten steps), and again on 1e5 (20 s) among the
#: slow tests, where float32 rounding has five times as long to accumulate
N = 20_000
N_LONG = 100_000

needs_cc = pytest.mark.skipif(
    CC is None and not os.environ.get("BWDESIGN_REQUIRE_CC"),
    reason="no C compiler (install gcc)",
)


def _build(out: Path, *extra: str) -> Path:
    assert CC is not None, "BWDESIGN_REQUIRE_CC is set but no C compiler was found"
    exe = out / "harness"
    cmd = [CC, *STRICT, *extra, *sorted(str(p) for p in out.glob("*.c")), "-lm", "-o", str(exe)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return exe


def _text(rows: np.ndarray) -> str:
    """The harness's input: one line per step, each value as repr (exact).

    The repr of the nested list, its brackets and spaces taken out: the same text as
    joining each value's repr (a float's repr has neither ", " nor "], ["), 1.2x faster.
    """
    rows = np.asarray(rows, float)
    assert rows.ndim == 2 and rows.size > 0
    inner = repr(rows.tolist())[2:-2]
    return inner.replace("], [", "\n").replace(", ", ",") + "\n"


def _parse(out: str) -> np.ndarray:
    """The harness's output ("a,b,...\n" per line) as a 2-D array, each value read exactly.

    np.fromstring parses in C (correctly rounded, as float() does), 1.2x faster than
    np.loadtxt; a line it cannot read stops it early, so the count is checked.
    """
    n_rows = out.count("\n")
    assert n_rows > 0 and out.endswith("\n"), f"harness output: {out[:80]!r}"
    n_cols = out[: out.index("\n")].count(",") + 1
    values = np.fromstring(out.replace("\n", ","), sep=",")
    assert values.size == n_rows * n_cols, "harness output not one row of numbers per line"
    return values.reshape(n_rows, n_cols)


def _run(exe: Path, mode: str, rows: np.ndarray | str) -> np.ndarray:
    text = rows if isinstance(rows, str) else _text(rows)
    res = subprocess.run([str(exe), mode], input=text, capture_output=True, text=True, check=True)
    return _parse(res.stdout)


def _inputs(dt: float, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """n-step held inputs (V): a sine, a triangle with minor loops, steps, noise."""
    t = np.arange(n) * dt
    tri = 2 / np.pi * np.arcsin(np.sin(2 * np.pi * 1.0 * t))
    minor = 8 * 2 / np.pi * np.arcsin(np.sin(2 * np.pi * 13.0 * t))
    steps = np.repeat(rng.uniform(0, 120, n // 2000 + 1), 2000)[:n]
    return {
        "sine": 70 + 40 * np.sin(2 * np.pi * t),
        "triangle_minor_loops": 60 + 45 * tri + minor,
        "steps": steps,
        "noise": 60 + 30 * np.sin(2 * np.pi * 0.5 * t) + rng.normal(0, 2.0, n),
    }


@pytest.fixture(scope="module")
def config():
    return load_config(CONFIG)


@pytest.fixture(scope="module", params=[N, pytest.param(N_LONG, marks=pytest.mark.slow)])
def length(request) -> int:
    """The records' length (:data:`N`; :data:`N_LONG` among the slow tests)."""
    return request.param


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@pytest.fixture(scope="module")
def records(config, length):
    """Per input of _inputs: (u, z, the harness input), simulated once for every observer test.

    z is the exact-model output with 10 nm sensor noise, drawn from the same seeded
    generator after the inputs, input by input (read-only arrays).
    """
    p, dt, n = config.plant, config.dt, length
    rng = np.random.default_rng(7)
    out = {}
    for name, u in _inputs(dt, rng, n).items():
        X = simulate_zoh(p, u, dt, x0=np.zeros(3))
        z = X[1:, 0] + rng.normal(0, 0.01, n)  # 10 nm sensor noise
        out[name] = (_frozen(u), _frozen(z), _text(np.column_stack([u, z])))
    return out


@pytest.fixture(scope="module")
def python_estimates(config, records):
    """``python_estimates(mode)``: the Python observer's batch_filter of every record.

    Computed once per observer (phso, eso, phdo) for both precisions (read-only arrays).
    """
    p, dt = config.plant, config.dt
    observers = {
        "phso": (HysteresisObserver, config.gains),
        "eso": (ExtendedStateObserver, config.gains),
        "phdo": (DisturbanceHysteresisObserver, disturbance_gains_from(config.gains)),
    }
    cache: dict[str, dict[str, np.ndarray]] = {}

    def estimates(mode: str) -> dict[str, np.ndarray]:
        if mode not in cache:
            cls, gains = observers[mode]
            cache[mode] = {
                name: _frozen(cls(p, gains, dt).batch_filter(z, u))
                for name, (u, z, _) in records.items()
            }
        return cache[mode]

    return estimates


@pytest.fixture(scope="module")
def builds(tmp_path_factory, config):
    if CC is None:
        pytest.skip("no C compiler")
    out = {}
    for precision in ("float64", "float32"):
        d = tmp_path_factory.mktemp(precision)
        export_c(config, d, precision=precision)
        out[precision] = _build(d)
    return out


@needs_cc
@pytest.mark.parametrize("precision, tol", [("float64", 1e-12), ("float32", 1e-4)])
@pytest.mark.parametrize("cls", [HysteresisObserver, ExtendedStateObserver], ids=["phso", "eso"])
def test_observer_matches_python(builds, records, python_estimates, precision, tol, cls):
    mode = "phso" if cls is HysteresisObserver else "eso"
    for name, (_, _, rows) in records.items():
        ref = python_estimates(mode)[name]
        got = _run(builds[precision], mode, rows)
        scale = np.ptp(ref, axis=0)
        err = np.max(np.abs(got - ref), axis=0) / scale
        assert got.shape == ref.shape
        assert np.all(err <= tol), f"{name}: relative error {err} > {tol}"


@needs_cc
@pytest.mark.parametrize("precision, tol", [("float64", 1e-12), ("float32", 1e-4)])
def test_phdo_matches_python(builds, records, python_estimates, precision, tol):
    """The PHDO's four states against DisturbanceHysteresisObserver.batch_filter.

    float64: each state within tol of its range (in fact 0.0, bit-identical). float32:
    x1, x2, x3 and the lumped x3 + d (what is certified and fed to the controller) within
    tol of their ranges; d within tol of the lumped state's range. On exact-model data d
    only follows the noise (range ~0.05 um) and absorbs, as it is built to, the float32
    rounding of the model constants (a static-gain error of ~1e-7, i.e. ~1 ulp of x1):
    its error is ~2e-5 um, 3e-4 to 5e-4 of its own range (the bench prints it).
    """
    for name, (_, _, rows) in records.items():
        ref = python_estimates("phdo")[name]
        got = _run(builds[precision], "phdo", rows)
        assert got.shape == ref.shape == (len(rows.splitlines()), 4)
        err = np.max(np.abs(got - ref), axis=0)
        lumped_ref, lumped = ref[:, 2] + ref[:, 3], got[:, 2] + got[:, 3]
        lumped_err = np.max(np.abs(lumped - lumped_ref)) / np.ptp(lumped_ref)
        rel = err[:3] / np.ptp(ref[:, :3], axis=0)
        assert np.all(rel <= tol), f"{name}: relative error of x1, x2, x3 {rel} > {tol}"
        assert lumped_err <= tol, f"{name}: lumped x3 + d error {lumped_err:.3g} > {tol}"
        assert err[3] <= tol * np.ptp(lumped_ref), f"{name}: d error {err[3]:.3g} um"
        if precision == "float64":
            assert err[3] <= tol * np.ptp(ref[:, 3]), f"{name}: d error {err[3]:.3g} um"


@pytest.fixture(scope="module")
def phdo_loop_run(config, length):
    """The Python PHDO loop of test_closed_loop_with_phdo_matches_python, run once.

    Both precisions replay the same run: t, z, x_d and its derivatives, u and xhat
    (read-only arrays).
    """
    p, dt, c = config.plant, config.dt, config.controller
    ref_traj = Triangle(amplitude=60.0, offset=100.0, frequency=2.0)
    loop = ClosedLoop(
        p,
        ObserverSpec("phdo", disturbance_gains_from(config.gains)),
        DiscreteTrackingController(p, c.lambda1, c.lambda2, dt=dt),
        dt=dt,
    )
    res = simulate(
        loop,
        ref_traj,
        duration=length * dt,
        true_params=replace(p, a1=1.02 * p.a1, a3=0.98 * p.a3),
        noise_std=0.01,
        seed=5,
        fast=False,
    )
    xd, vd, ad = (np.asarray(a) for a in ref_traj.evaluate(res.t))
    arrays = {"z": res.z, "xd": xd, "vd": vd, "ad": ad, "u": res.u, "xhat": res.xhat}
    return res.stable, {k: _frozen(v) for k, v in arrays.items()}


@needs_cc
@pytest.mark.parametrize("precision, tol", [("float64", 1e-12), ("float32", 1e-4)])
def test_closed_loop_with_phdo_matches_python(builds, phdo_loop_run, precision, tol):
    """The controller fed by the PHDO's lumped estimate, as bwdesign.simulate runs the loop.

    The Python loop (generic path: the objects themselves) runs a plant with a1 +2 % and
    a3 -2 % (the PHDO's case: d has work to do) and 10 nm noise; the harness replays its
    measurements z_k (phdo-loop) and must give the same inputs u_k and estimates. float64
    closes the loop on its own u_k (bit-identical, so the replay is the loop). float32
    predicts with the applied u_k as logged (the fifth column): a replay without the plant
    has a neutral direction (a shift dw of the lumped estimate moves u by (a1/a3) dw through
    the law, and that u makes the observer's model agree with the frozen z again), so on its
    own u_k float32 rounding walks along it (measured: 0.19 of u's range over 1e5 steps); in
    the real loop the plant answers u and pins it.
    """
    stable, res = phdo_loop_run
    assert stable and res["u"].shape == (len(res["z"]),) and len(res["z"]) > 1000
    cols = [res["z"], res["xd"], res["vd"], res["ad"]] + (
        [res["u"]] if precision == "float32" else []
    )
    got = _run(builds[precision], "phdo-loop", np.column_stack(cols))
    want = np.column_stack([res["u"], res["xhat"]])
    err = np.max(np.abs(got - want), axis=0) / np.ptp(want, axis=0)
    assert np.all(err <= tol), f"u, x1, x2, x3 + d: relative error {err} > {tol}"


@pytest.fixture(scope="module")
def controller_inputs(config, length):
    """The controllers' inputs (noisy estimates, a 1 Hz sine) as the harness reads them,
    and each law's Python output.

    Computed once for both precisions (read-only arrays).
    """
    p, dt, c, n = config.plant, config.dt, config.controller, length
    rng = np.random.default_rng(3)
    t = np.arange(n) * dt
    xd = 100 + 80 * np.sin(2 * np.pi * t)
    vd = 80 * 2 * np.pi * np.cos(2 * np.pi * t)
    ad = -80 * (2 * np.pi) ** 2 * np.sin(2 * np.pi * t)
    xhat = np.column_stack([xd, vd, np.zeros(n)]) + rng.normal(0, [0.5, 50.0, 0.1], (n, 3))
    rows = np.column_stack([xhat, xd, vd, ad])
    refs = {}
    for mode, ctl in (
        ("controller", DiscreteTrackingController(p, c.lambda1, c.lambda2, dt=dt)),
        ("eq12", TrackingController(p, c.lambda1, c.lambda2)),
    ):
        refs[mode] = _frozen([ctl(r[:3], tuple(r[3:])) for r in rows])
    return _text(rows), refs


@needs_cc
@pytest.mark.parametrize("precision, tol", [("float64", 1e-12), ("float32", 1e-4)])
def test_controllers_match_python(builds, controller_inputs, precision, tol):
    rows, refs = controller_inputs
    for mode, ref in refs.items():
        got = _run(builds[precision], mode, rows)[:, 0]
        err = np.max(np.abs(got - ref)) / np.ptp(ref)
        assert err <= tol, f"{mode}: relative error {err:.3g} > {tol}"


@needs_cc
def test_digital_tuning_with_integral_and_saturation(tmp_path, config, paper_tuning):
    """The digital-tuning form (integral action) and amplifier limits, against Python."""
    from bwdesign.model.config import ControllerSettings

    cfg = replace(
        config, controller=ControllerSettings(lambda1=1.0, lambda2=2.0, u_min=0.0, u_max=100.0)
    )
    res = export_c(cfg, tmp_path, gains_from="digital")
    exe = _build(tmp_path)
    tune = paper_tuning  # digital_tuning(cfg.plant, cfg.dt)
    ctl = DiscreteTrackingController(
        cfg.plant,
        tune.lambda1,
        tune.lambda2,
        dt=cfg.dt,
        integral_rate=tune.integral_rate,
        u_limits=(0.0, 100.0),
    )
    rng = np.random.default_rng(11)
    n = 20_000
    rows = np.column_stack(
        [
            rng.normal(100, 30, (n, 1)),
            rng.normal(0, 300, (n, 1)),
            rng.normal(0, 1, (n, 1)),
            rng.normal(100, 30, (n, 1)),
            rng.normal(0, 300, (n, 1)),
            rng.normal(0, 1e4, (n, 1)),
        ]
    )
    ref = np.array([ctl(r[:3], tuple(r[3:])) for r in rows])
    got = _run(exe, "controller", rows)[:, 0]
    assert ref.min() == 0.0 and ref.max() == 100.0  # the limits were exercised
    assert np.max(np.abs(got - ref)) / np.ptp(ref) <= 1e-12
    assert res.document["controller"]["integral_rate"] == tune.integral_rate
    obs = HysteresisObserver(cfg.plant, tune.gains, cfg.dt)
    assert res.document["observers"]["phso"]["K"] == obs.K.tolist()


def _shared_library(out: Path) -> ctypes.CDLL:
    lib = out / "libbw.so"
    subprocess.run(
        [CC, *STRICT, "-shared", "-fPIC", str(out / "bw.c"), "-lm", "-o", str(lib)],
        check=True,
        capture_output=True,
    )
    return ctypes.CDLL(str(lib))


class _Observer(ctypes.Structure):
    _fields_ = [
        ("x", ctypes.c_double * 3),
        ("x_prior", ctypes.c_double * 3),
        ("x1_lo", ctypes.c_double),
        ("u_prev", ctypes.c_double),
        ("guard_trips", ctypes.c_ulong),
        ("uncovered", ctypes.c_int),
    ]


@needs_cc
def test_runtime_guard_flags_uncertified_steps(tmp_path, config):
    res = export_c(config, tmp_path)
    lib = _shared_library(tmp_path)
    du_max = res.summary["udot_max"] * config.dt
    s = _Observer()
    lib.bw_phso_init(ctypes.byref(s))
    step = lib.bw_phso_step
    step.argtypes = [ctypes.POINTER(_Observer), ctypes.c_double, ctypes.c_double]
    step(ctypes.byref(s), 0.9 * du_max, 0.0)  # within the certified rate
    assert (s.uncovered, s.guard_trips) == (0, 0)
    step(ctypes.byref(s), 0.9 * du_max + 1.01 * du_max, 0.0)  # beyond it
    assert (s.uncovered, s.guard_trips) == (1, 1)
    step(ctypes.byref(s), s.u_prev, 0.0)
    assert (s.uncovered, s.guard_trips) == (0, 1)
    header = (tmp_path / "bw.h").read_text()
    assert "CERTIFIED by the sampled tier" in header
    assert "#define BW_UDOT_MAX" in header and "#define BW_DT" in header


def test_a_template_missing_a_value_is_an_internal_error():
    """A template asking for a value the exporter does not give is a bug: loud, not bad input."""
    from bwdesign.codegen.export import fill

    with pytest.raises(InternalError, match=r"template observer.h.tmpl: no value for \$"):
        fill("observer.h.tmpl")


def test_literals_are_exact():
    for v in (0.1, -512.0, 159827.5, 1e-300, 2.0**-1074, 0.0015987206823946071):
        assert float.fromhex(c_literal(v, "float64")) == v
        lit = c_literal(v, "float32")
        assert lit.endswith("f") and float.fromhex(lit[:-1]) == float(np.float32(v))
    with pytest.raises(ValueError, match="non-finite"):
        c_literal(float("nan"), "float64")
    with pytest.raises(ValueError, match="overflows float32"):
        c_literal(1e39, "float32")


@needs_cc
def test_float32_code_has_no_double(tmp_path, config):
    export_c(config, tmp_path, precision="float32")
    src = (tmp_path / "bw.c").read_text()
    assert "double" not in src
    for fn in ("expm1f(", "log1pf(", "fabsf("):
        assert fn in src
    # and no double-precision libm call (the jump needs no exp: expm1 gives its decay)
    code = re.sub(r"/\*.*?\*/", "", src, flags=re.S)
    assert not re.search(r"\b(exp|expm1|log1p|fabs)\(", code)
    # every floating constant carries the f suffix
    consts = re.findall(r"0x[0-9a-f.]+p[+-]\d+\w?", src)
    assert consts and all(c.endswith("f") for c in consts)


def test_synthesized_gains(tmp_path, config):
    """--synthesize exports the gains bwdesign report synthesises, certified at the envelope."""
    from bwdesign import synthesize

    res = export_c(config, tmp_path, gains_from="synthesize")
    syn = synthesize(config.plant, udot_max=config.envelope().udot_max, decay=100.0, dt=config.dt)
    assert res.certified and syn.feasible
    assert res.document["observers"]["phso"]["K"] == pytest.approx(list(syn.discrete_gains))
    assert "observer gains from synthesize" in (tmp_path / "bw.h").read_text()


def test_uncertified_gains_are_refused(tmp_path, config):
    # the paper's gains at 1e5 V/s, 25x what any tier certifies for them
    bad = replace(config, envelope_spec={"udot_max": 1e5})
    with pytest.raises(NotCertifiedError, match="no certificate tier holds"):
        export_c(bad, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    res = export_c(bad, tmp_path / "out", allow_uncertified=True)
    assert not res.certified
    header = (tmp_path / "out" / "bw.h").read_text()
    assert "NOT CERTIFIED" in header
    # the constant's own comment does not call the bound certified (issue 24)
    lines = header.splitlines()
    line = lines[lines.index(f"#define BW_UDOT_MAX ({c_literal(1e5, 'float64')})") - 1]
    assert "NOT certified for it" in line and "are certified for" not in line
    good = (tmp_path / "good").joinpath("bw.h")
    export_c(config, tmp_path / "good")
    assert "/* The input-rate bound |u'| (V/s) the observer gains are certified for. */" in (
        good.read_text()
    )


def _stage(tmp_path: Path, text: str) -> str:
    p = tmp_path / "stage.toml"
    p.write_text(text)
    return str(p)


_PLANT = """[plant]
a1 = 159827.5
a2 = 713.8
a3 = 222665.02
alpha = 0.4795
beta = {beta}
gamma = 0.0378
"""
_DT = "[sampling]\ndt = 2e-4\n"
_GAINS = """[observer]
gains = [8.0, 64.0, -512.0]
"""
_REST = """[controller]
lambda1 = 1.0
lambda2 = 2.0
[envelope]
udot_max = 400.0
"""


@pytest.mark.parametrize(
    "label, argv, stage, message",
    [
        ("unknown observer", ["--observer", "ukf"], None, "invalid choice"),
        ("unknown precision", ["--precision", "float16"], None, "invalid choice"),
        ("bad prefix", ["--prefix", "9lives"], None, "C identifier"),
        ("no dt", [], _PLANT.format(beta=0.3762) + _GAINS + _REST, r"\[sampling\] dt"),
        ("no gains", [], _PLANT.format(beta=0.3762) + _DT + _REST, r"\[observer\] gains"),
        ("unbounded plant", [], _PLANT.format(beta=-1.3567) + _DT + _GAINS + _REST, "bounded"),
    ],
)
def test_bad_input(tmp_path, capsys, label, argv, stage, message):
    cfg = _stage(tmp_path, stage) if stage else str(CONFIG)
    out = tmp_path / "out"
    code = main(["export-c", "--config", cfg, "--out", str(out), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, label
    assert err[-1].startswith("error:") and "Traceback" not in "".join(err)
    assert re.search(message, err[-1]), err[-1]
    assert not out.exists()


def test_unwritable_output_is_an_error(tmp_path, capsys):
    target = tmp_path / "afile"
    target.write_text("user data\n")
    code = main(["export-c", "--config", str(CONFIG), "--out", str(target)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("error:")
    assert target.read_text() == "user data\n"


def test_cli_json(tmp_path, capsys):
    code = main(["export-c", "--config", str(STACK), "--out", str(tmp_path / "c"), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0
    assert doc["certificate"]["certified"] and doc["files"] == [
        "bw.h",
        "bw.c",
        "harness.c",
        "export.json",
    ]


@pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None, reason="no arm-none-eabi-gcc")
@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_cross_compiles_for_cortex_m4f(tmp_path, config, precision):
    export_c(config, tmp_path, precision=precision)
    assert "bw_phdo_step" in (tmp_path / "bw.c").read_text()
    obj = tmp_path / "bw.o"
    flags = ["-mcpu=cortex-m4", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard", "-mthumb"]
    subprocess.run(
        ["arm-none-eabi-gcc", *STRICT, "-Os", *flags, "-c", str(tmp_path / "bw.c"), "-o", str(obj)],
        check=True,
        capture_output=True,
    )
    size = subprocess.run(["arm-none-eabi-size", str(obj)], capture_output=True, text=True)
    assert size.returncode == 0 and "text" in size.stdout


class _PhdoObserver(ctypes.Structure):
    _fields_ = [
        ("x", ctypes.c_double * 4),
        ("x_prior", ctypes.c_double * 4),
        ("x1_lo", ctypes.c_double),
        ("u_prev", ctypes.c_double),
        ("guard_trips", ctypes.c_ulong),
        ("uncovered", ctypes.c_int),
    ]


@needs_cc
def test_phdo_guard_and_lumped_estimate(tmp_path, config):
    """bw_phdo_*: the runtime guard as the PHSO's, and bw_phdo_lumped = (x1, x2, x3 + d)."""
    res = export_c(config, tmp_path)
    lib = _shared_library(tmp_path)
    du_max = res.summary["udot_max"] * config.dt
    s = _PhdoObserver()
    lib.bw_phdo_init(ctypes.byref(s))
    lib.bw_phdo_step.argtypes = [ctypes.POINTER(_PhdoObserver), ctypes.c_double, ctypes.c_double]
    lib.bw_phdo_step(ctypes.byref(s), 0.9 * du_max, 0.0)
    assert (s.uncovered, s.guard_trips) == (0, 0)
    lib.bw_phdo_step(ctypes.byref(s), 0.9 * du_max + 1.01 * du_max, 0.5)
    assert (s.uncovered, s.guard_trips) == (1, 1)
    py = DisturbanceHysteresisObserver(
        config.plant, disturbance_gains_from(config.gains), config.dt
    )
    py.predict(0.9 * du_max)
    py.update(0.0)
    py.predict(0.9 * du_max + 1.01 * du_max)
    py.update(0.5)
    assert list(s.x) == py.x.tolist() and py.x[3] != 0.0
    xhat = (ctypes.c_double * 3)()
    lib.bw_phdo_lumped(ctypes.byref(s), xhat)
    assert list(xhat) == py.x_lumped.tolist()
    header = (tmp_path / "bw.h").read_text()
    assert "PHDO lumped error CERTIFIED by the sampled tier" in header
    assert "void bw_phdo_lumped(const bw_phdo_observer *s, bw_real xhat[3]);" in header


@needs_cc
def test_harness_default_observer_phdo(tmp_path, capsys, config):
    """export-c --observer phdo: the harness runs the PHDO without a mode argument."""
    code = main(["export-c", "--config", str(CONFIG), "--out", str(tmp_path), "--observer", "phdo"])
    assert code == 0 and "PHDO lumped error by the sampled tier" in capsys.readouterr().out
    exe = _build(tmp_path)
    u = 70 + 40 * np.sin(2 * np.pi * np.arange(2000) * config.dt)
    z = 1.39 * u - 1.0
    text = "\n".join(f"{a!r},{b!r}" for a, b in zip(u.tolist(), z.tolist(), strict=True))
    out = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True)
    got = np.loadtxt(out.stdout.splitlines(), delimiter=",")
    gains = disturbance_gains_from(config.gains)
    ref = DisturbanceHysteresisObserver(config.plant, gains, config.dt).batch_filter(z, u)
    assert got.shape == (2000, 4) and np.array_equal(got, ref)
    doc = json.loads((tmp_path / "export.json").read_text())
    assert doc["harness_observer"] == "phdo"
    assert doc["observers"]["phdo"]["gains"] == list(gains)
    assert doc["observers"]["phdo"]["certificate"]["holds"]
    assert doc["certificate"]["phdo"]["certified"] and doc["certificate"]["certified"]


def test_phdo_gains_per_source(tmp_path, config, paper_tuning):
    """--tuning digital: observer_gains_for("phdo"); --synthesize: the synthesised K lumped."""
    res = export_c(config, tmp_path / "digital", gains_from="digital")
    g = paper_tuning.observer_gains_for("phdo")  # digital_tuning(config.plant, config.dt)
    phdo = res.document["observers"]["phdo"]
    assert phdo["gains"] == list(g) and "observer_gains_for('phdo')" in phdo["gains_from"]
    assert phdo["K"] == DisturbanceHysteresisObserver(config.plant, g, config.dt).K.tolist()
    res = export_c(config, tmp_path / "syn", gains_from="synthesize")
    k1, k2, k3 = res.document["observers"]["phso"]["K"]
    phdo = res.document["observers"]["phdo"]
    assert phdo["K"] == [k1, k2, 0.0, k3]  # the exported PHSO's observable poles
    assert phdo["gains"] == list(disturbance_gains_from(res.document["gains"]))
    assert "synthesised gains in the lumped form" in phdo["gains_from"]
    assert phdo["certificate"]["holds"] and res.certified


def test_uncertified_phdo_is_refused(tmp_path, config, monkeypatch):
    """The PHDO's lumped certificate counts as the PHSO's does (exit 1 unless allowed)."""
    import bwdesign.codegen.export as export

    real = export.certify_disturbance

    def failing(*args, **kwargs):
        return replace(real(*args, **kwargs), holds=False, status="not certified: forced")

    monkeypatch.setattr(export, "certify_disturbance", failing)
    with pytest.raises(NotCertifiedError, match="PHDO's lumped error is not certified"):
        export_c(config, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    res = export_c(config, tmp_path / "out", allow_uncertified=True)
    assert not res.certified and res.summary["tier"] == "sampled"
    header = (tmp_path / "out" / "bw.h").read_text()
    assert "PHDO lumped error NOT CERTIFIED (not certified: forced" in header
    assert "PHSO/ESO gains CERTIFIED by the sampled tier" in header
