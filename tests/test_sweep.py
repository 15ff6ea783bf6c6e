"""Batched simulation and Monte Carlo sweeps: agreement with simulate, independence of chunking."""

from __future__ import annotations

import json
import re
import socket
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bwdesign import (
    ClosedLoop,
    DiscreteTrackingController,
    ObserverSpec,
    Sine,
    Start,
    TrackingController,
    Triangle,
    UncertaintyBox,
    hysteresis_increment,
    preset,
    simulate,
)
from bwdesign.cli.main import main
from bwdesign.control.loop import ON_REFERENCE
from bwdesign.design import stage_tuning
from bwdesign.errors import ConfigError, InputError, ParameterError
from bwdesign.model.config import load_config
from bwdesign.model.envelope import derive_envelope
from bwdesign.sim.batch import hysteresis_increment_batch, simulate_batch
from bwdesign.sim.compiled import hysteresis_jump
from bwdesign.sim.replay import SENSITIVE_RTOL, SENSITIVITY_STEP, replay_row
from bwdesign.sim.sweep import (
    MEMORY_CAP,
    ROW_BYTES,
    SweepError,
    SweepSpec,
    check_samples,
    check_scheduler,
    check_workers,
    draw_scenarios,
    max_samples,
    max_workers,
    run_sweep,
    spec_from_config,
    sweep_box,
)
from bwdesign.study.sweep import sweep_summary

DT = 2e-4
P = preset("paper_experiment")
BOX = UncertaintyBox.parse("a1=2%,a2=2%,a3=2%,alpha=10%,beta=10%,gamma=10%")
EXACT = UncertaintyBox()  # every parameter exact: the scenarios differ in noise only


@pytest.fixture
def tune(paper_tuning):
    return paper_tuning  # digital_tuning(P, DT) (conftest)


def _loop(ctl, observer, gains, **kw):
    """``observer`` on ``gains`` (the PHDO on ``(l1, l2, 0, l3)`` of 3) with the law ``ctl``."""
    return ClosedLoop(P, ObserverSpec.of(observer, gains), ctl, dt=DT, **kw)


def _mismatched(n, seed):
    cols = draw_scenarios(P, BOX, n, seed=seed)
    return [replace(P, **{k: float(cols[k][i]) for k in BOX.widths}) for i in range(n)], cols


def test_stacked_zoh_matches_discretize():
    from bwdesign.model.plant import discretize
    from bwdesign.sim.zoh import true_matrices

    tps = [P, preset("paper_simulation_corrected"), replace(P, a1=1e9, a2=10.0), replace(P, a2=5e4)]
    T = true_matrices(tps, DT)
    for i, tp in enumerate(tps):
        z = discretize(tp, DT)
        got = [[T[f"p{r + 1}{c + 1}"][i] for c in range(3)] for r in range(2)]
        assert got == z.F[:2].tolist()  # the same matrices as one run's (sim/zoh.py)
        assert [T["g1"][i], T["g2"][i]] == z.g[:2].tolist()


def test_hysteresis_batch_matches_scalar():
    rng = np.random.default_rng(0)
    for p in (P, preset("paper_simulation_corrected"), replace(P, gamma=-0.3)):
        h = rng.uniform(-1.5, 1.5, 4000) * p.alpha / (p.beta + p.gamma)
        u0 = rng.uniform(-50, 50, 4000)
        u1 = u0 + rng.choice([0.0, 1e-9, 0.3, -0.3, 40.0, -40.0], 4000)
        got = hysteresis_increment_batch(p.alpha, p.beta, p.gamma, h, u0, u1)
        ref = np.array([hysteresis_increment(p, *a) for a in zip(h, u0, u1, strict=True)])
        np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-15)
        # the compiled jump of the batched loop (bwdesign.sim.compiled): same operations
        jit = [hysteresis_jump(p.alpha, p.beta, p.gamma, *a) for a in zip(h, u0, u1, strict=True)]
        np.testing.assert_allclose(jit, ref, rtol=1e-14, atol=1e-16)


@pytest.mark.parametrize("observer", ["phso", "eso", "phdo"])
@pytest.mark.parametrize(
    "label, kw",
    [
        ("plain", {}),
        ("delay", {"delay": True}),
        ("delay, stale", {"delay": True, "compensate_delay": False}),
    ],
)
def test_batch_matches_simulate(tune, observer, label, kw):
    tps, cols = _mismatched(5, seed=2)
    ref = Triangle(amplitude=60, offset=80, frequency=2, corner_time=0.02)
    ctl = DiscreteTrackingController(
        P, tune.lambda1, tune.lambda2, dt=DT, integral_rate=tune.integral_rate, u_limits=(0, 100)
    )
    seeds = cols["noise_seed"]
    loop = _loop(ctl, observer, tune.gains, **kw)
    assert loop.observer.gains == tune.observer_gains_for(observer)
    b = simulate_batch(loop, ref, tps, duration=1.0, noise_std=0.02, seeds=seeds)
    for i, tp in enumerate(tps):
        r = simulate(loop, ref, duration=1.0, true_params=tp, noise_std=0.02, seed=int(seeds[i]))
        assert b.stable[i] == r.stable and b.status[i] == r.status
        m = r.metrics
        got = [b.me[i], b.maxe[i], b.rmse[i], *b.estimation_rmse[i], b.saturated_fraction[i]]
        want = [m.me, m.maxe, m.rmse, *r.estimation_rmse, r.saturated_fraction]
        # the same operations on the same numbers (sim/zoh.py, sim/compiled.py): to the bit
        assert [float(v) for v in got] == want
        # the input's largest step and second difference over the window, from its samples
        inw = (r.t >= r.window[0] - 1e-12) & (r.t <= r.window[1] + 1e-12)
        du = np.diff(r.u, prepend=r.u[0])  # the run starts from u_prev = u[0] here
        d2 = np.diff(du, prepend=0.0)
        assert b.input_rate_max[i] == pytest.approx(np.max(np.abs(du[inw])) / DT, rel=1e-12)
        assert b.input_accel_max[i] == pytest.approx(np.max(np.abs(d2[inw])) / DT**2, rel=1e-9)


def test_the_agreement_scenarios_are_not_sensitive_to_rounding(tune):
    """test_batch_matches_simulate's scenarios are not chaotic.

    A change of a1 in its 12th digit moves their metrics by ~1e-9 (an amplification
    of ~1e3; a chaotic loop moves them by 1e-5 .. 1e-2). The batched and the scalar loop
    now agree to the bit; should a rounding difference come back (~1e-16), it would stay
    near 1e-13 on these scenarios: a failure there is about the loop, not about chaos.
    """
    tps, cols = _mismatched(5, seed=2)
    ref = Triangle(amplitude=60, offset=80, frequency=2, corner_time=0.02)
    ctl = DiscreteTrackingController(
        P, tune.lambda1, tune.lambda2, dt=DT, integral_rate=tune.integral_rate, u_limits=(0, 100)
    )
    loop = _loop(ctl, "phso", tune.gains)
    kw = dict(duration=1.0, noise_std=0.02, seeds=cols["noise_seed"])
    a = simulate_batch(loop, ref, tps, **kw)
    b = simulate_batch(loop, ref, [replace(t, a1=t.a1 * (1 + SENSITIVITY_STEP)) for t in tps], **kw)
    assert a.stable.all()
    for m in ("me", "maxe"):
        change = np.abs(getattr(b, m) / getattr(a, m) - 1)
        assert change.max() < SENSITIVE_RTOL, (m, change)


def test_batch_detects_divergence_per_scenario():
    """An eq. 12 loop with the paper's constants and a 3x a3 error diverges; the rest does not."""
    tps = [P, replace(P, a3=3 * P.a3), replace(P, a1=1.01 * P.a1)]
    ctl = TrackingController(P, 200.0, 200.0, estimate_limits=None)
    ref = Sine(amplitude=40, offset=60, frequency=2)
    gains = (2286.2, 1208283.0, -6256.75)
    loop = _loop(ctl, "phso", gains)
    b = simulate_batch(loop, ref, tps, duration=0.5)
    for i, tp in enumerate(tps):
        r = simulate(loop, ref, duration=0.5, true_params=tp)
        assert (b.stable[i], b.status[i]) == (r.stable, r.status)
        if r.stable:  # the scenario run beside the diverged one (and the odd last) exact
            assert b.me[i] == r.metrics.me
    assert not b.stable[1] and b.stable[0] and np.isnan(b.me[1])
    # in either place of the kernel's pair, alone or last: the same answer
    for order in ([1, 0, 2], [0, 2, 1], [1]):
        bo = simulate_batch(loop, ref, [tps[i] for i in order], duration=0.5)
        for k, i in enumerate(order):
            assert (bo.stable[k], bo.status[k]) == (b.stable[i], b.status[i])
            assert bo.me[k] == b.me[i] or (np.isnan(bo.me[k]) and np.isnan(b.me[i]))


def test_draw_depends_only_on_the_seed():
    bounds = BOX.check(P)
    assert list(bounds) == list(BOX.widths) == ["a1", "a2", "a3", "alpha", "beta", "gamma"]
    a = draw_scenarios(P, BOX, 50, seed=7)
    b = draw_scenarios(P, BOX, 50, seed=7)
    c = draw_scenarios(P, BOX, 50, seed=8)
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert not np.array_equal(a["a1"], c["a1"])
    for k, (lo, hi) in bounds.items():
        assert np.all((a[k] >= lo) & (a[k] <= hi))
    n = draw_scenarios(P, BOX, 2000, seed=1, distribution="normal")
    for k, (lo, hi) in bounds.items():
        assert np.all((n[k] >= lo) & (n[k] <= hi))
        # truncated at the 95 % interval: the spread is narrower than the uniform's
        assert np.std(n[k]) < (hi - lo) / np.sqrt(12)


def _spec(tune, observers=("phso", "eso")):
    ctl = DiscreteTrackingController(
        P, tune.lambda1, tune.lambda2, dt=DT, integral_rate=tune.integral_rate
    )
    return SweepSpec(
        loop=_loop(ctl, "phso", tune.gains, start=ON_REFERENCE),
        reference=Sine(amplitude=80, offset=100, frequency=5),
        duration=0.4,
        gains=tuple(tune.gains),
        observers=observers,
        noise_std=0.02,
    )


#: The digital tuning's PHSO loop on a 2 Hz sine, 1.5 s: at the nominal plant its input
#: stays inside the envelope and the loop is not sensitive to rounding; at the corner
#: a1 + 2 %, a3 - 2 % (measured) its input chatters at ~7x the envelope and a change of a1
#: in its 12th digit moves MAXE by ~1e-2: chaotic.
CHAOS_REF = Sine(amplitude=80, offset=100, frequency=2)


@pytest.fixture(scope="module")
def corner_sweep(paper_tuning_session):
    tune = paper_tuning_session  # read only
    ctl = DiscreteTrackingController(
        P, tune.lambda1, tune.lambda2, dt=DT, integral_rate=tune.integral_rate
    )
    env = derive_envelope(P, CHAOS_REF, margin=1.1).udot_max
    spec = SweepSpec(
        loop=_loop(ctl, "phso", tune.gains, start=ON_REFERENCE),
        reference=CHAOS_REF,
        duration=1.5,
        gains=tuple(tune.gains),
        observers=("phso",),
        udot_max=env,
        envelope_source="the reference's, margin 1.1",
    )
    sc = draw_scenarios(P, EXACT, 2, seed=0)  # scenario 0 nominal, scenario 1 the corner
    sc["a1"][1], sc["a3"][1] = 1.02 * P.a1, 0.98 * P.a3
    return spec, run_sweep(spec, sc, workers=0)


def test_rows_say_whether_the_input_stayed_in_the_envelope(corner_sweep):
    spec, table = corner_sweep
    rate = table["input_rate_max"]
    assert table["within_envelope"].tolist() == [True, False]
    assert rate[0] <= spec.udot_max < 5 * spec.udot_max < rate[1]
    s = sweep_summary(table, udot_max=spec.udot_max)["phso"]
    assert (s["outside_envelope"], s["fraction_outside_envelope"]) == (1, 0.5)
    assert s["worst_envelope_ratio"] == pytest.approx(rate[1] / spec.udot_max, rel=1e-15)
    assert s["input_rate_max"] == {"max": rate[1], "worst_scenario": 1}
    # the column is the scalar loop's max |u_k - u_(k-1)| / dt over the window (nominal row)
    rep = replay_row(spec, table, 0, "phso")
    assert rep.replayed["input_rate_max"] == pytest.approx(rate[0], rel=1e-9)
    # no envelope named: rates recorded, nothing compared
    bare = replace(spec, udot_max=None, duration=1.0)
    bare = run_sweep(bare, draw_scenarios(P, EXACT, 1), workers=0)
    assert "within_envelope" not in bare and 0 < bare["input_rate_max"][0] < np.inf
    assert sweep_summary(bare)["phso"]["outside_envelope"] is None


def test_a_replay_says_whether_its_row_reproduces(corner_sweep):
    """The report's replay: the nominal row reproduces, the chaotic corner only statistically."""
    spec, table = corner_sweep
    calm = replay_row(spec, table, 0, "phso")
    assert calm.sensitive is False
    assert calm.replay_difference < 1e-9 and calm.perturbation_change < 1e-9
    assert calm.replayed["maxe"] == pytest.approx(table["maxe"][0], rel=1e-9)
    wild = replay_row(spec, table, 1, "phso")
    assert wild.sensitive is True
    assert wild.perturbation_change > SENSITIVE_RTOL
    assert wild.to_dict()["row"]["maxe"] == table["maxe"][1]
    with pytest.raises(InputError, match="no row for scenario 7"):
        replay_row(spec, table, 7, "phso")


def _equal(a, b):
    assert a.keys() == b.keys()
    for k in a:
        if a[k].dtype.kind == "f":
            assert np.array_equal(a[k], b[k], equal_nan=True), k
        else:
            assert np.array_equal(a[k], b[k]), k


def test_result_does_not_depend_on_chunks(tune):
    spec = _spec(tune)
    sc = draw_scenarios(P, BOX, 12, seed=4)
    one = run_sweep(spec, sc, chunk_size=12, workers=0)
    many = run_sweep(spec, sc, chunk_size=5, workers=0)
    _equal(one, many)
    assert one["scenario"].tolist() == sorted(list(range(12)) * 2)
    assert set(one["observer"]) == {"phso", "eso"}


@pytest.mark.slow
def test_local_cluster_equals_single_process(tune):
    """A real dask.distributed LocalCluster with two worker processes, row for row."""
    pytest.importorskip("distributed")
    spec = _spec(tune)
    sc = draw_scenarios(P, BOX, 16, seed=5)
    _equal(
        run_sweep(spec, sc, chunk_size=16, workers=0), run_sweep(spec, sc, chunk_size=3, workers=2)
    )


def test_a_scheduler_that_does_not_answer_times_out(tune):
    pytest.importorskip("distributed")
    with socket.socket() as s:  # a port on this machine that nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    sc = draw_scenarios(P, EXACT, 2, seed=0)
    with pytest.raises(SweepError, match="no Dask scheduler answered"):
        run_sweep(_spec(tune, ("phso",)), sc, scheduler=f"tcp://127.0.0.1:{port}", timeout=0.5)
    # a well-formed tls:// address without a TLS configuration: said, not a TypeError
    with pytest.raises(SweepError, match="could not connect .* TLS"):
        run_sweep(_spec(tune, ("phso",)), sc, scheduler=f"tls://127.0.0.1:{port}", timeout=0.5)


def test_a_failing_chunk_is_reported_not_dropped(tune, monkeypatch):
    import bwdesign.sim.sweep as sweep

    calls = []

    def flaky(spec, cols):
        calls.append(1)
        if int(cols["scenario"][0]) == 4:
            raise RuntimeError("worker lost")
        return real(spec, cols)

    real = sweep.run_chunk
    monkeypatch.setattr(sweep, "run_chunk", flaky)
    sc = draw_scenarios(P, EXACT, 8, seed=0)
    with pytest.raises(SweepError, match=r"scenarios 4\.\.7 failed after 2 retries"):
        run_sweep(_spec(tune, ("eso",)), sc, chunk_size=4, workers=0, retries=2)
    assert len(calls) == 1 + 3  # the good chunk once, the bad one 1 + 2 retries


def test_bad_inputs(tune):
    with pytest.raises(InputError, match="> 0"):
        draw_scenarios(P, EXACT, 0)
    with pytest.raises(ParameterError, match="bounded class"):
        draw_scenarios(P, UncertaintyBox.parse("beta=95%"), 3)  # beta - gamma < 0 at a corner
    with pytest.raises(ParameterError, match="a3 must keep its sign"):
        draw_scenarios(P, UncertaintyBox.parse("a3=150%"), 3)
    with pytest.raises(InputError, match="UncertaintyBox"):
        draw_scenarios(P, {"a1": ("rel", 0.02)}, 3)  # the old dict shape
    with pytest.raises(ParameterError, match="bounded class"):
        replace(_spec(tune), box=UncertaintyBox.parse("beta=95%"))  # the spec checks its box


def test_a_listed_exact_parameter_is_drawn_at_its_nominal():
    """``a2=0%`` lists a2 but does not vary it: nominal, also for the normal draw (which
    crashed on main: the clip of a scalar gave a 0-d column)."""
    box = UncertaintyBox.parse("a1=2%,a2=0%")
    assert list(box.check(P)) == ["a1"]
    for dist in ("uniform", "normal"):
        cols = draw_scenarios(P, box, 5, seed=1, distribution=dist)
        assert cols["a2"].shape == (5,) and np.all(cols["a2"] == P.a2)
        same = draw_scenarios(P, UncertaintyBox.parse("a1=2%"), 5, seed=1, distribution=dist)
        assert all(np.array_equal(cols[k], same[k]) for k in cols)


def test_the_sweep_box_comes_from_the_stage_or_the_argument():
    config = load_config("configs/stack_actuator_800hz.toml")
    assert sweep_box(config) is config.uncertainty
    mine = UncertaintyBox.parse("a1=1%")
    assert sweep_box(config, mine) is mine
    assert spec_from_config(config, uncertainty=mine).box is mine
    assert spec_from_config(config).box == config.uncertainty
    bare = load_config("configs/paper_experiment.toml")  # no [uncertainty]
    with pytest.raises(ConfigError, match=r"no \[uncertainty\] section"):
        sweep_box(bare)
    with pytest.raises(ConfigError, match=r"no \[uncertainty\] section"):
        spec_from_config(bare)
    undetermined = UncertaintyBox.from_dict({"a1": {"rel": float("inf")}})
    with pytest.raises(ParameterError, match="a1 not determined"):
        sweep_box(bare, undetermined)


def test_the_sweep_runs_the_law_its_caller_tuned(paper_tuning):
    """spec_from_config chooses no gains: the law it is given, else the stage's own."""
    config = load_config("configs/paper_experiment.toml")
    box = UncertaintyBox.parse("a1=2%")
    law = stage_tuning(config, "digital")
    assert law.gains == paper_tuning.gains  # digital_tuning(config.plant, config.dt)
    tuned = spec_from_config(config, law=law, uncertainty=box)
    assert tuned.gains == law.gains != tuple(config.gains)
    assert tuned.loop.controller.lambda1 == law.lambda1
    assert stage_tuning(config, "config") is None
    assert spec_from_config(config, uncertainty=box).gains == tuple(config.gains)
    with pytest.raises(InputError, match="tuning must be 'config' or 'digital'"):
        stage_tuning(config, "fast")
    with pytest.raises(ConfigError, match=r"the digital tuning needs \[sampling\] dt"):
        stage_tuning(replace(config, dt=None), "digital")
    with pytest.raises(ConfigError, match=r"a sweep needs \[observer\] gains"):
        spec_from_config(replace(config, gains=None), uncertainty=box)
    assert spec_from_config(replace(config, gains=None), law=law, uncertainty=box).gains == (
        law.gains
    )


def test_a_stage_sweep_compares_with_the_stages_envelope(tmp_path):
    """[envelope] when the stage has one (the certificates' assumption), else the reference's."""
    config = load_config("configs/paper_experiment.toml")
    box = UncertaintyBox.parse("a1=2%")
    spec = spec_from_config(config, uncertainty=box)
    assert spec.udot_max == config.envelope().udot_max and "margin 1.1" in spec.envelope_source
    text = Path("configs/paper_experiment.toml").read_text()
    start, end = text.index("[envelope]"), text.index("[requirements]")
    (tmp_path / "s.toml").write_text(text[:start] + text[end:])
    bare = spec_from_config(load_config(tmp_path / "s.toml"), uncertainty=box)
    assert bare.udot_max == derive_envelope(P, config.reference).udot_max
    assert "no [envelope]" in bare.envelope_source


def test_limits_are_checked_before_any_work(tune, monkeypatch):
    import os

    import bwdesign.sim.sweep as sweep

    cpus = os.cpu_count() or 1
    assert max_workers() == 2 * cpus and check_workers(max_workers()) == max_workers()
    with pytest.raises(InputError, match=f"at most {2 * cpus} worker processes"):
        check_workers(max_workers() + 1)
    for good in ("tcp://127.0.0.1:8786", "tls://sched.lab.example:8786", "host:1", "[::1]:8786"):
        assert check_scheduler(good) == good
    for bad in ("notaurl", "tcp://host", "tcp://host:0", "tcp://host:65536", "http://h:80", ""):
        with pytest.raises(InputError, match="HOST:PORT"):
            check_scheduler(bad)
    limit = max_samples(2)
    assert limit == max_samples(1) // 2  # floor(floor(x) / 2) = floor(x / 2)
    assert max_samples(1) * ROW_BYTES <= MEMORY_CAP and check_samples(limit, 2) == limit
    with pytest.raises(InputError, match=f"at most {limit} scenarios with 2 observer"):
        check_samples(limit + 1, 2)
    with pytest.raises(InputError, match="phso given 2 times"):
        _spec(tune, ("phso", "eso", "phso"))
    with pytest.raises(InputError, match="udot_max"):
        replace(_spec(tune), udot_max=-1.0)
    with pytest.raises(InputError, match="loop must be a ClosedLoop"):
        replace(_spec(tune), loop=P)

    def no_work(*a, **k):
        raise AssertionError("a chunk ran")

    monkeypatch.setattr(sweep, "run_chunk", no_work)
    sc = draw_scenarios(P, EXACT, 2)
    for kw, match in (
        ({"workers": max_workers() + 1}, "worker processes"),
        ({"scheduler": "notaurl"}, "HOST:PORT"),
    ):
        with pytest.raises(InputError, match=match):
            run_sweep(_spec(tune), sc, **kw)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--samples", "0"], "expected an integer > 0"),
        (["--samples", "-5"], "expected an integer > 0"),
        (["--samples", "3", "--uncertainty", "beta=95%"], "bounded class"),
        (["--samples", "3", "--uncertainty", "zeta=2%"], "NAME=WIDTH"),
        (["--samples", "3"], r"no \[uncertainty\] section"),
        (["--samples", "3", "--uncertainty", "a1=2%", "--seed", "-1"], "integer >= 0"),
        (["--samples", "3", "--uncertainty", "a1=2%", "--observers", "ukf"], "sweep observers"),
        (["--samples", "3", "--uncertainty", "a1=2%", "--observers", "phso,PHSO"], "once"),
        (["--samples", "3", "--uncertainty", "a1=2%,a1=3%"], "a1 given twice"),
        (["--samples", "3", "--uncertainty", "a1=2%", "--workers", "1000"], "at most"),
        (["--samples", "100000000", "--uncertainty", "a1=2%"], r"at most \d+ scenarios"),
        (["--samples", "3", "--uncertainty", "a1=2%", "--scheduler", "notaurl"], "HOST:PORT"),
    ],
)
def test_cli_bad_input(tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    code = main(["sweep", "--config", "configs/paper_experiment.toml", "--out", str(out), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("error:")
    assert re.search(message, err[-1]), err[-1]
    assert not out.exists()


def test_cli_writes_table_and_report(tmp_path, capsys):
    pq = pytest.importorskip("pyarrow.parquet")
    out = tmp_path / "sw"
    code = main(
        [
            "sweep",
            "--config",
            "configs/paper_experiment.toml",
            "--samples",
            "6",
            "--uncertainty",
            "a1=2%,alpha=10%",
            "--tuning",
            "digital",
            "--duration",
            "0.4",
            "--workers",
            "0",
            "--quiet",
            "--json",
            "--out",
            str(out),
        ]
    )
    doc = json.loads(capsys.readouterr().out)
    assert code == 0
    t = pq.read_table(out / "scenarios.parquet").to_pydict()
    assert t["scenario"] == sorted(list(range(6)) * 2)
    for col in ("a1", "alpha", "noise_seed", "maxe", "me", "rmse", "est_rmse_x1", "stable"):
        assert col in t
    assert doc["summary"]["phso"]["scenarios"] == 6
    assert (out / "report.md").exists() and (out / "figures" / "histograms.png").exists()
    # every row: its largest input rate and whether it stayed in the certified envelope
    udot = load_config("configs/paper_experiment.toml").envelope().udot_max
    assert doc["columns"] == list(t) and t["within_envelope"] == [
        s and r <= udot for s, r in zip(t["stable"], t["input_rate_max"], strict=True)
    ]
    for obs, s in doc["summary"].items():
        sel = [o == obs for o in t["observer"]]
        out_ = sum(not w for w, k in zip(t["within_envelope"], sel, strict=True) if k)
        assert (s["udot_max"], s["outside_envelope"]) == (udot, out_)
        assert s["replay"]["sensitive"] is (
            max(s["replay"]["replay_difference"], s["replay"]["perturbation_change"]) > 1e-6
        )
    md = (out / "report.md").read_text()
    assert f"assume |u'| <= {udot:.4g} V/s" in md and "replayed with simulate()" in md
    # the reference as a sentence, not a Python dict (issue 24)
    md = (out / "report.md").read_text()
    assert "; sine 80 sin(2 pi 1 t) + 100; " in md and "{'kind'" not in md


def test_missing_extra_names_it(tmp_path, capsys, monkeypatch):
    """Without tqdm (the sweep extra) the progress bar is one error line naming the extra."""
    import sys

    monkeypatch.setitem(sys.modules, "tqdm", None)  # import tqdm now raises ModuleNotFoundError
    out = tmp_path / "sw"
    code = main(
        [
            "sweep",
            "--config",
            "configs/paper_experiment.toml",
            "--samples",
            "2",
            "--uncertainty",
            "a1=2%",
            "--workers",
            "0",
            "--out",
            str(out),
        ]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("error:")
    assert "pip install 'bwdesign[sweep]'" in err[-1]
    assert not out.exists()


def test_report_includes_the_configs_sweep(tmp_path, capsys):
    """[sweep] in the stage file: the report runs a small sweep over [uncertainty].

    Over three of the box's six parameters: the sweep draws its scenarios from whatever
    box the stage has, and the robust section, which the report also computes over the
    box, costs a few seconds at 8 corners instead of a minute at 64 (the 64-corner
    report is test_report_has_the_robust_section in tests/test_robust.py, slow).
    """
    text = Path("configs/stack_actuator_800hz.toml").read_text()
    for name in ("a2", "a3", "gamma"):
        text = text.replace(f"\n{name} = {{ rel", f"\n# {name} = {{ rel")
    text = text.replace("samples = 100", "samples = 4").replace(
        "[sweep]", "[sweep]\nduration_s = 0.05"
    )
    stage = tmp_path / "stage.toml"
    stage.write_text(text)
    out = tmp_path / "r"
    assert main(["report", "--config", str(stage), "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    md = (out / "report.md").read_text()
    assert "## Robustness over the uncertainty box (Monte Carlo)" in md
    cert = json.loads((out / "certificate.json").read_text())
    assert cert["sweep"]["samples"] == 4 and set(cert["sweep"]["summary"]) == {"phso", "eso"}
    assert list(cert["sweep"]["bounds"]) == ["a1", "alpha", "beta"]
    assert (out / "figures" / "sweep_histograms.png").exists()
    # the robust section says what its bounds are made of, as certificate.json has them
    for rl in cert["robust"]["observers"].values():
        parts = rl["certificate"]["details"]["tracking_bound_parts"]
        assert sum(parts.values()) == pytest.approx(rl["tracking_bound"], rel=1e-9)
        top = max(parts, key=parts.get)
        share = 100 * parts[top] / sum(parts.values())
        assert f"{rl['observer'].upper()}: {top} {share:.1f} %" in md


@pytest.mark.parametrize(
    "edit, message",
    [
        (("[uncertainty]", "[not_uncertainty]"), r"unknown section"),
        (
            ("samples = 100", "samples = 0"),
            r"\[sweep\] samples = 0 is outside the supported range \[1, inf\)",
        ),
        (("samples = 100", 'samples = 100\ntuning = "fast"'), r"\[sweep\] tuning must be one of"),
        (("samples = 100", 'samples = 100\nobservers = ["ukf"]'), r"\[sweep\] observers"),
        (("samples = 100", 'samples = 100\nobservers = ["eso", "eso"]'), r"given once"),
        (("samples = 100", "samples = 100000000"), r"\[sweep\] samples: .* at most \d+"),
    ],
)
def test_report_sweep_bad_input(tmp_path, capsys, edit, message):
    text = Path("configs/stack_actuator_800hz.toml").read_text().replace(*edit)
    stage = tmp_path / "stage.toml"
    stage.write_text(text)
    out = tmp_path / "r"
    assert main(["report", "--config", str(stage), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("error:") and re.search(message, err[-1]), err[-1]
    assert not out.exists()


def test_report_sweep_needs_an_uncertainty_box(tmp_path, capsys):
    text = Path("configs/stack_actuator_800hz.toml").read_text()
    start, end = text.index("[uncertainty]"), text.index("[sweep]")
    stage = tmp_path / "stage.toml"
    stage.write_text(text[:start] + text[end:])
    out = tmp_path / "r"
    assert main(["report", "--config", str(stage), "--out", str(out), "--quiet"]) == 2
    assert "no [uncertainty] section" in capsys.readouterr().err
    assert not out.exists()


def test_sweep_runs_the_disturbance_observer(tune):
    """The PHDO in a sweep: the tuning's (l1, l2, 0, l3), the same rows as simulate_batch."""
    from bwdesign.observers.gains import disturbance_gains_from

    spec = _spec(tune, ("phso", "phdo"))
    sc = draw_scenarios(P, BOX, 4, seed=2)
    table = run_sweep(spec, sc, chunk_size=4, workers=0)
    assert set(table["observer"]) == {"phso", "phdo"}
    tps, _ = _mismatched(4, seed=2)
    assert spec.loop_for("phdo").observer.gains == disturbance_gains_from(spec.gains)
    loop = ClosedLoop(
        P,
        ObserverSpec("phdo", disturbance_gains_from(spec.gains)),
        spec.controller,
        dt=DT,
        start=Start.on_reference(P, spec.reference),
    )
    ref = simulate_batch(
        loop,
        spec.reference,
        tps,
        duration=spec.duration,
        noise_std=spec.noise_std,
        seeds=sc["noise_seed"],
    )
    np.testing.assert_array_equal(table["me"][table["observer"] == "phdo"], ref.me)


@pytest.mark.parametrize(
    "seed, n, scale", [(0, 0, 0.02), (1, 1, 1.0), (7, 5001, 0.02), (2**40, 333, 3.5)]
)
def test_compiled_noise_is_numpys(seed, n, scale):
    """The batch draws its noise with numba's Generator: numpy's numbers, to the bit."""
    from bwdesign.sim.compiled import scaled_normals

    out = np.full(n, np.nan)
    scaled_normals(np.random.default_rng(seed), out, scale)
    assert np.array_equal(out, scale * np.random.default_rng(seed).standard_normal(n))


@pytest.mark.parametrize("bounded", [False, True])
def test_noise_rows_are_each_seeds_own_numbers(bounded):
    """noise_rows reuses one Generator, its state set row by row: each row is still
    ``std * default_rng(seed).standard_normal(n)`` (or its sign), whatever came before it
    (a seed repeated, rows of zero std between, odd lengths that leave a half-used word)."""
    from bwdesign.sim.compiled import noise_rows

    seeds = np.array([3, 2**40, 3, 0, 17, 9])
    std = np.array([0.02, 1.0, 0.5, 0.0, -1.0, 3.5])
    for n in (1, 7, 5000):
        rows = np.full((len(seeds), n), np.nan)
        noise_rows(seeds, std, bounded, rows)
        for i, (seed, s) in enumerate(zip(seeds.tolist(), std.tolist(), strict=True)):
            draw = np.random.default_rng(seed).standard_normal(n)
            want = np.zeros(n) if s <= 0 else s * (np.sign(draw) if bounded else draw)
            assert np.array_equal(rows[i], want), (seed, s, n)


def _tuned_or_baseline(tune, observer):
    """The tuned law with ``observer``, or (``"baseline"``) the stage's tuned PI loop."""
    from bwdesign import tune_baseline

    if observer == "baseline":
        return ClosedLoop(P, None, tune_baseline(P, DT), dt=DT)
    ctl = DiscreteTrackingController(
        P, tune.lambda1, tune.lambda2, dt=DT, integral_rate=tune.integral_rate
    )
    return _loop(ctl, observer, tune.gains)


@pytest.mark.parametrize("observer", ["phso", "baseline"])
def test_bounded_noise_is_at_its_bound_and_the_batch_matches_simulate(tune, observer):
    """noise_kind="bounded": +-noise_std at every sample (the bound a certificate covers),
    drawn from the same seed; the batch equals simulate to the bit, as for Gaussian noise."""
    tps, _ = _mismatched(3, seed=4)
    ref = Sine(amplitude=60, offset=80, frequency=2)
    loop = _tuned_or_baseline(tune, observer)
    kw = dict(duration=0.5, noise_std=0.02, noise_kind="bounded")
    b = simulate_batch(loop, ref, tps, seeds=[3, 4, 5], **kw)
    for i, tp in enumerate(tps):
        r = simulate(loop, ref, true_params=tp, seed=3 + i, **kw)
        noise = np.asarray(r.z) - np.asarray(r.x)[:, 0]
        assert np.allclose(np.abs(noise), 0.02, rtol=1e-9)  # z = x1 + n, rounded
        assert r.settings["noise_kind"] == "bounded" and b.settings["noise_kind"] == "bounded"
        assert [float(b.me[i]), float(b.maxe[i]), float(b.rmse[i])] == [
            r.metrics.me,
            r.metrics.maxe,
            r.metrics.rmse,
        ]
    gauss = simulate(loop, ref, true_params=tps[0], seed=3, duration=0.5, noise_std=0.02)
    assert gauss.metrics.maxe != b.maxe[0]
    with pytest.raises(InputError, match="noise_kind"):
        simulate(loop, ref, duration=0.5, noise_kind="uniform")
    with pytest.raises(InputError, match="noise_kind"):
        simulate_batch(loop, ref, tps, duration=0.5, noise_kind="uniform")


@pytest.mark.parametrize("observer", ["phdo", "baseline"])
def test_a_noise_pattern_is_the_noise_and_the_batch_matches_simulate(tune, observer):
    """noise_kind as a pattern: noise_std times the given values, sample by sample (the
    falsifier's aimed noise); one row per scenario in the batch, equal to simulate's to the
    bit; a pattern outside [-1, 1], of the wrong length or not finite is refused."""
    tps, _ = _mismatched(2, seed=5)
    ref = Sine(amplitude=60, offset=80, frequency=2)
    loop = _tuned_or_baseline(tune, observer)
    n = int(round(0.5 / DT))
    rows = np.random.default_rng(8).uniform(-1, 1, (2, n))
    b = simulate_batch(loop, ref, tps, duration=0.5, noise_std=0.03, noise_kind=rows)
    assert b.settings["noise_kind"] == "pattern"
    for i, tp in enumerate(tps):
        r = simulate(loop, ref, true_params=tp, duration=0.5, noise_std=0.03, noise_kind=rows[i])
        assert np.allclose(np.asarray(r.z) - np.asarray(r.x)[:, 0], 0.03 * rows[i], atol=1e-12)
        assert r.settings["noise_kind"] == "pattern"
        assert [float(b.maxe[i]), float(b.rmse[i])] == [r.metrics.maxe, r.metrics.rmse]
    one = simulate_batch(loop, ref, tps, duration=0.5, noise_std=0.03, noise_kind=rows[0])
    assert one.maxe[0] == b.maxe[0]  # one row for every scenario
    for bad in (1.5 * rows[0], rows[0][:-1], np.where(rows[0] > 0.9, np.nan, rows[0])):
        with pytest.raises(InputError, match="noise_kind"):
            simulate(loop, ref, duration=0.5, noise_std=0.03, noise_kind=bad)
    with pytest.raises(InputError, match="noise_kind"):
        simulate_batch(loop, ref, tps, duration=0.5, noise_std=0.03, noise_kind=rows[:, :-1])


def test_corners_with_noise_at_the_bound_move_the_input_faster(tune):
    """A certificate with |n| <= noise_max must face the input rate that noise causes:
    simulate_corners(noise_max=...) runs it (bounded noise), the design's envelope reads it."""
    ctl = DiscreteTrackingController(
        P, tune.lambda1, tune.lambda2, dt=DT, integral_rate=tune.integral_rate
    )
    loop = _loop(ctl, "phdo", tune.gains, start=ON_REFERENCE)
    ref = Sine(amplitude=60, offset=80, frequency=2)
    from bwdesign.sim.corners import simulate_corners

    quiet = simulate_corners(loop, BOX, ref)
    noisy = simulate_corners(loop, BOX, ref, noise_max=0.2)
    assert noisy.settings["noise_kind"] == "bounded"
    assert np.max(noisy.input_rate_max) > 1.2 * np.max(quiet.input_rate_max)


def test_noise_free_corners_are_not_labelled_bounded(tune):
    from bwdesign.sim.corners import simulate_corners

    ctl = DiscreteTrackingController(
        P, tune.lambda1, tune.lambda2, dt=DT, integral_rate=tune.integral_rate
    )
    res = simulate_corners(
        _loop(ctl, "phdo", tune.gains), BOX, Sine(amplitude=60, offset=80, frequency=2)
    )
    assert "noise_kind" not in res.settings
