"""Identification acceptance: round trips, interval coverage, an unmodelled amplifier lag.

Heavy (seconds per fit on 5k-10k samples): marked slow. Each test prints its
numbers (run with ``-s`` to see them).
"""

from __future__ import annotations

import numpy as np
import pytest

from bwdesign import BoucWenParams, identify, preset
from bwdesign.identify.excite import design_excitation, simulate_record

NAMES = ("a1", "a2", "a3", "alpha", "beta", "gamma")

#: name -> (plant, dt, duration, umin, umax, udot_max)
STAGES = {
    # 8 s (40 000 samples): its hysteresis spans only 1.16 um against 10 nm of noise and
    # gamma is a tenth of beta; on 8 s gamma's 95 % half-width is 1.75 % with the input
    # spanning 3-117 V of the 0-120 V range (1.35 % when it used only 29-92 V of it)
    "paper_experiment": (preset("paper_experiment"), 2e-4, 8.0, 0.0, 120.0, 2000.0),
    "paper_simulation_corrected": (
        preset("paper_simulation_corrected"),
        1e-4,
        1.0,
        0.0,
        6.0,
        2e4,
    ),
    # gamma < 0 (bounded: beta + gamma > 0 and beta - gamma >= 0), 300 Hz
    "gamma_negative": (
        BoucWenParams(
            a1=3553057.6,
            a2=376.99,
            a3=2842446.1,
            alpha=0.3,
            beta=0.05,
            gamma=-0.03,
            name="gamma_negative",
        ),
        1e-4,
        1.0,
        0.0,
        100.0,
        3000.0,
    ),
    # a 1.5 kHz resonance (zeta 0.05) at a 10 kHz loop
    "resonance_1k5_at_10k": (
        BoucWenParams(
            a1=88826440.0,
            a2=942.48,
            a3=10659172.8,
            alpha=0.1,
            beta=0.05,
            gamma=0.02,
            name="resonance_1k5_at_10k",
        ),
        1e-4,
        1.0,
        -20.0,
        120.0,
        5e4,
    ),
}


#: Targets not met, with the reason (none since the paper stage's record is 8 s long).
NOT_MET: set[tuple[str, str]] = set()


def _records(name, seed=0, noise=0.01, amplifier_lag=None):
    plant, dt, duration, umin, umax, udot = STAGES[name]
    kw = dict(umin=umin, umax=umax, udot_max=udot, dt=dt)
    _, u = design_excitation(plant, duration=duration, seed=seed, **kw)
    _, uv = design_excitation(plant, kind="triangle-sweep", duration=duration / 2, seed=7, **kw)
    common = dict(noise=noise, offset=3.0, amplifier_lag=amplifier_lag)
    train = simulate_record(plant, u, dt, seed=100 + seed, **common)
    valid = simulate_record(plant, uv, dt, seed=200 + seed, **common)
    return plant, train, valid


@pytest.mark.slow
@pytest.mark.parametrize("name", list(STAGES))
def test_round_trip_default_excitation_without_init(name):
    plant, train, valid = _records(name)
    res = identify(train, validation=valid)
    errs = {n: 100 * (getattr(res.params, n) / getattr(plant, n) - 1) for n in NAMES}
    half = {n: 100 * 1.96 * res.std_err[n] / abs(getattr(plant, n)) for n in NAMES}
    print(
        f"\n{name}: N={train.n} fit train {res.fit_percent['train']:.3f} % validation "
        f"{res.fit_percent['validation']:.3f} % in {res.seconds:.1f} s"
    )
    for n in NAMES:
        print(f"  {n:6s} error {errs[n]:+8.4f} %   95 % half-width {half[n]:7.4f} %")
    assert res.converged, res.reason
    assert res.fit_percent["validation"] >= 99.5
    for n in NAMES:
        if (name, n) in NOT_MET:
            # the record's information, not the fit, limits it: the 95 % half-width
            # itself is above 1 % (see NOT_MET); the error stays within 1.5 of it
            assert half[n] > 1.0 and abs(errs[n]) < 1.5 * half[n], (n, errs[n], half[n])
        else:
            assert abs(errs[n]) < 1.0, (n, errs[n])


@pytest.mark.slow
def test_interval_coverage_over_20_noise_realisations():
    """95 % intervals contain the truth in >= 17 of 20 seeded realisations, per parameter."""
    name = "gamma_negative"
    plant, dt, _, umin, umax, udot = STAGES[name]
    _, u = design_excitation(plant, umin=umin, umax=umax, udot_max=udot, duration=1.0, dt=dt)
    hits = dict.fromkeys(NAMES, 0)
    for seed in range(20):
        rec = simulate_record(plant, u, dt, noise=0.01, offset=3.0, seed=1000 + seed)
        res = identify(rec, multistart=1)
        assert res.converged, res.reason
        for n in NAMES:
            lo, hi = res.ci95[n]
            hits[n] += int(lo <= getattr(plant, n) <= hi)
    print(f"\ncoverage of the 95 % intervals over 20 realisations ({name}): {hits}")
    assert all(h >= 17 for h in hits.values()), hits


@pytest.mark.slow
def test_unmodelled_amplifier_lag_bias_is_reported():
    """A first-order amplifier at 3x the resonance, not in the model: bias and validation fit."""
    name = "paper_experiment"
    plant = STAGES[name][0]
    tau_amp = 1.0 / (3.0 * np.sqrt(plant.a1))
    _, train, valid = _records(name, amplifier_lag=tau_amp)
    res = identify(train, validation=valid)
    errs = {n: 100 * (getattr(res.params, n) / getattr(plant, n) - 1) for n in NAMES}
    print(
        f"\namplifier lag {tau_amp * 1e3:.3f} ms (3x the resonance): fit train "
        f"{res.fit_percent['train']:.3f} %, validation {res.fit_percent['validation']:.3f} %"
    )
    print("  bias: " + ", ".join(f"{n} {e:+.2f} %" for n, e in errs.items()))
    for d in res.diagnostics:
        print("  note:", d)
    assert res.converged
    # the model cannot represent the lag: it still predicts the validation record well,
    # but with biased parameters, and the result says something is off
    assert res.fit_percent["validation"] > 99.0
    assert max(abs(e) for e in errs.values()) > 1.0
    assert any("residuals are not white" in d for d in res.diagnostics)


@pytest.mark.slow
@pytest.mark.parametrize(
    "stage,fs",
    [("paper_experiment", 5000.0), ("configs/stack_actuator_800hz.toml", 200.0)],
    ids=["experiment_5kHz", "stack_800Hz_at_200Hz"],
)
def test_slow_sine_bench_record_resonance_unseen(stage, fs):
    """1 Hz sine, 7 um offset, starting mid-cycle: gain and loop fitted, resonance flagged."""
    from bwdesign import load_plant, simulate_zoh

    plant = load_plant(stage)
    dt = 1.0 / fs
    n_pre, n = int(1.3 * fs), int(5 * fs)
    t = np.arange(n_pre + n) * dt
    mid, amp = (60.0, 50.0) if plant.name == "paper_experiment" else (50.0, 50.0)
    u = mid + amp * np.sin(2 * np.pi * t + 0.4)
    x = simulate_zoh(plant, u[:n_pre], dt, np.zeros(3), u_prev=u[0])
    rec = simulate_record(plant, u[n_pre:], dt, noise=0.01, offset=7.0, x0=tuple(x[-1]), seed=3)
    res = identify(rec)
    print(f"\n{stage} at {fs:g} Hz: " + "; ".join(res.diagnostics))
    assert res.converged, res.reason
    assert [n_ for n_ in NAMES if not res.determined[n_]] == ["a1", "a2", "a3"]
    k = res.derived["static_gain"]
    # Known limit: at 200 Hz the stack's lightly damped 800 Hz mode (zeta 0.05) aliases
    # into the record; with it held at the default the gain is 0.52 % low while its
    # interval (conditional on the held resonance) is +-0.5 %: within 1 %, not covered.
    assert abs(k["value"] / plant.static_gain - 1) < 0.01
    # the loop parameters are determined; the same aliasing can push them just outside
    # their (conditional) intervals, so allow 1.5 half-widths
    for n_ in ("alpha", "beta", "gamma"):
        lo, hi = res.ci95[n_]
        half = 0.5 * (hi - lo)
        assert res.determined[n_]
        assert abs(getattr(res.params, n_) - getattr(plant, n_)) <= 1.5 * half, n_
    assert abs(res.offset - 7.0) < 0.05


def _lagged(u, dt, tau):
    a = np.exp(-dt / tau)
    out, s = np.empty_like(u), u[0]
    for k, v in enumerate(u):
        s = a * s + (1 - a) * v
        out[k] = s
    return out


@pytest.mark.slow
def test_a_record_the_model_misses_part_of_still_converges(tmp_path):
    """The issue's stall: a 200 Hz slow-sine record of a stage with creep and a 2 ms
    amplifier lag the model lacks (plus offset, drift, 16-bit quantisation, a mid-cycle
    start). The fit is far above a static linear one, so it must end converged and
    write the stage file; before the stationary test it exhausted its 200 evaluations
    ("did not converge") with train fit 99.3 %."""
    import subprocess
    import sys

    from bwdesign.model.plant import simulate_zoh

    p, dt_sim = preset("paper_experiment"), 1e-4
    t = np.arange(0.0, 8027 / 200, dt_sim)
    u = 60 + 55 * np.sin(2 * np.pi * t + 1.1)
    ul = _lagged(u, dt_sim, 2e-3)
    uc = ul + 0.04 * _lagged(ul, dt_sim, 0.3) + 0.03 * _lagged(ul, dt_sim, 3.0)
    y = simulate_zoh(p, uc, dt_sim, np.zeros(3))[1:, 0][::50]
    t, u = t[::50], u[::50]
    rng = np.random.default_rng(1)
    y = y + 3.0 + 0.02 * t + rng.normal(0, 1e-4 * np.ptp(y), y.size)
    q = 1.5 * np.ptp(y) / 65536
    y = np.round(y / q) * q
    f = tmp_path / "rec.csv"
    np.savetxt(f, np.column_stack([t, u, y]), delimiter=",", header="t,u,y", comments="")
    out = tmp_path / "stage.toml"
    r = subprocess.run(
        [sys.executable, "-m", "bwdesign", "identify", "--data", str(f), "--out", str(out)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert out.is_file() and "fit 99." in r.stdout
