"""Linear analysis of the tracking loop, checked against simulation."""

import json
import math

import numpy as np
import pytest

from bwdesign import (
    ClosedLoop,
    ObserverSpec,
    Start,
    Step,
    analyze_loop,
    make_controller,
    mismatch_sweep,
    simulate,
)
from bwdesign.control.analysis import stability_interval
from bwdesign.design.tuning import MarginRequirements, digital_tuning, observer_gains
from bwdesign.errors import InputError
from bwdesign.memo import Memo
from bwdesign.model.plant import discretize
from bwdesign.observers.gains import discrete_gains, error_matrix
from bwdesign.output.jsonenc import json_safe

DT = 2e-4
PAPER_GAINS = (8.0, 64.0, -512.0)
HOLD = Step(amplitude=0.0, offset=10.0)  # a constant reference: free decay of the loop


def lin(p, lambda1, lambda2, gains=PAPER_GAINS, *, dt=None, form="continuous", **kw):
    """The PHSO on ``gains`` with eq. (12) in ``form`` (``integral_rate``), sampled at ``dt``."""
    law = make_controller(
        p, lambda1, lambda2, form=form, dt=dt, integral_rate=kw.pop("integral_rate", None)
    )
    return ClosedLoop(p, ObserverSpec.of("phso", gains), law, dt=dt, **kw)


def loop(p, observer, gains, lambda1, lambda2, *, form="continuous", jump=False, **kw):
    """``observer`` on ``gains`` with eq. (12) in ``form``, sampled at DT."""
    law = make_controller(p, lambda1, lambda2, form=form, dt=DT, hysteresis_jump=jump)
    return ClosedLoop(p, ObserverSpec.of(observer, gains), law, dt=DT, **kw)


def decay_rate(r, t0, t1):
    """Decay rate (1/s) of |e| fitted by least squares on log|e| over [t0, t1]."""
    s = (r.t >= t0) & (r.t <= t1)
    return -np.polyfit(r.t[s], np.log(np.abs(r.e[s])), 1)[0]


def test_continuous_loop_separates(usable_plant):
    """Exact model: poles = {-lambda1, -lambda2} and the observer's (separation principle)."""
    p = usable_plant
    gains = PAPER_GAINS if p.name == "paper_experiment" else (80.0, 160.0, -640.0)
    a = analyze_loop(lin(p, 3.0, 70.0, gains))
    want = np.concatenate([[-3.0, -70.0], np.linalg.eigvals(error_matrix(p, gains))])
    assert np.allclose(np.poly(a.poles), np.poly(want), rtol=1e-7)
    assert a.stable and a.spectral_radius is None
    assert abs(a.tracking_gain(1.0)) < 1e-9  # perfect feedforward in continuous time


def test_sampled_discrete_form_places_poles(experiment):
    g = observer_gains(experiment, [-1000.0] * 3)
    a = analyze_loop(lin(experiment, 50.0, 400.0, g, dt=DT, form="discrete"))
    zobs = np.linalg.eigvals(
        (np.eye(3) - np.outer(discrete_gains(experiment, g, DT), [1, 0, 0]))
        @ discretize(experiment, DT).F
    )
    want = np.concatenate([np.exp(-np.array([50.0, 400.0]) * DT), zobs])
    assert np.allclose(np.poly(a.poles), np.poly(want), atol=1e-10)
    assert a.spectral_radius == pytest.approx(math.exp(-50.0 * DT), rel=1e-9)


def test_paper_constants_sampled_poles(experiment):
    """eq. (12) as printed at 0.2 ms: the designed -1, -2 1/s become about -0.104 and -18."""
    a = analyze_loop(lin(experiment, 1.0, 2.0, PAPER_GAINS, dt=DT))
    s = np.sort(a.poles_s.real)[::-1]
    assert a.stable
    assert s[0] == pytest.approx(-0.1039, rel=1e-3)
    assert s[1] == pytest.approx(-17.96, rel=1e-3)
    # the mechanism: to first order the ZOH lag of a1 x1hat adds a velocity feedback
    # a1 dt / 2 (16 1/s) to the designed lambda1 + lambda2 = 3 1/s
    assert -(s[0] + s[1]) == pytest.approx(3.0 + experiment.a1 * DT / 2, rel=0.06)
    assert abs(a.tracking_gain(1.0)) == pytest.approx(0.802, rel=1e-3)


def test_sampled_poles_match_simulated_decay(experiment):
    """The slowest pole of the analysis is the decay rate of the simulated tracking error."""
    g = tuple(observer_gains(experiment, [-1000.0] * 3))
    a = analyze_loop(lin(experiment, 50.0, 400.0, g, dt=DT, form="discrete"))
    lp = loop(experiment, "phso", g, 50.0, 400.0, form="discrete", start=Start(xhat0=(2, 0, 0)))
    r = simulate(lp, HOLD, duration=0.13)
    assert decay_rate(r, 0.04, 0.12) == pytest.approx(a.slowest_decay_rate, rel=0.01)
    assert a.slowest_decay_rate == pytest.approx(-math.log(a.spectral_radius) / DT, rel=1e-9)


def test_paper_constants_decay_matches_analysis_not_design(experiment):
    """0.104 1/s predicted for the sampled loop (designed: 1 1/s), and simulated.

    The linear analysis holds x3; the law cancels the post-jump hysteresis
    estimate only with ``hysteresis_jump=True``, and then the match is exact.
    """
    a = analyze_loop(lin(experiment, 1.0, 2.0, PAPER_GAINS, dt=DT))
    lp = loop(experiment, "phso", PAPER_GAINS, 1.0, 2.0, jump=True, start=Start(xhat0=(2, 0, 0)))
    r = simulate(lp, HOLD, duration=20.01)
    rate = decay_rate(r, 8.0, 20.0)
    assert rate == pytest.approx(a.slowest_decay_rate, rel=0.005)
    assert rate < 0.2  # nowhere near the designed slowest pole of 1 1/s


def test_steady_state_error_matches_tracking_gain(experiment):
    """abs(E/X_d) of the analysis = the simulated error amplitude of the Table 2 sine."""
    from bwdesign import Sine

    a = analyze_loop(lin(experiment, 1.0, 2.0, PAPER_GAINS, dt=DT))
    lp = loop(experiment, "phso", PAPER_GAINS, 1.0, 2.0, start=Start(x0=(100.0, 0.0, 0.0)))
    r = simulate(lp, Sine(amplitude=80.0, offset=100.0, frequency=1.0), duration=70.0)
    amp = 0.5 * np.ptp(r.e[r.t >= 68.0])
    assert amp == pytest.approx(80.0 * abs(a.tracking_gain(1.0)), rel=0.02)


def test_gain_margin_matches_simulation(experiment):
    """Loop gain 5 % inside / outside the analysed interval: decays / grows in simulation.

    ESO and a plant with negligible hysteresis: the loop is then exactly the
    analysed linear one. (The PHSO's hysteresis copy dissipates an oscillation of
    x3hat at every input reversal and catches the unstable mode in a limit cycle:
    there the linear analysis is conservative.)
    """
    p = experiment.replace(alpha=1e-9)
    a = analyze_loop(lin(p, 1.0, 2.0, PAPER_GAINS, dt=DT))
    k_max = a.gain_margin[1]
    assert 1.3 < k_max < 1.6
    swings = {}
    for k in (0.95, 1.05):
        lp = loop(p, "eso", PAPER_GAINS, 1.0, 2.0, start=Start(xhat0=(2.0, 0.0, 0.0)))
        r = simulate(lp, HOLD, duration=2.0, true_params=p.replace(a3=p.a3 * k * k_max))
        v = r.x[:, 1]  # the oscillatory mode shows in the velocity
        swings[k] = np.max(np.abs(v[r.t > 1.5])) / np.max(np.abs(v[(r.t > 0.2) & (r.t < 0.7)]))
    assert swings[0.95] < 0.5 and swings[1.05] > 2.0


def test_phase_margin_cross_check(experiment):
    """python-control's phase margin against a dense evaluation of the loop transfer."""
    g = tuple(observer_gains(experiment, [-1000.0] * 3))
    a = analyze_loop(lin(experiment, 240.0, 240.0, g, dt=DT, form="discrete", integral_rate=120.0))
    w = np.geomspace(1.0, math.pi / DT, 100_000)
    L = np.squeeze(a.systems.loop(np.exp(1j * w * DT)))
    i = np.flatnonzero(np.diff(np.sign(np.abs(L) - 1.0)))
    pm = 180.0 + np.degrees(np.angle(L[i]))
    j = int(np.argmin(np.abs(pm)))
    assert a.phase_margin == pytest.approx(pm[j], abs=0.1)
    assert a.crossover == pytest.approx(w[i[j]], rel=1e-3)
    assert a.delay_margin == pytest.approx(math.radians(a.phase_margin) / a.crossover)


@pytest.mark.parametrize("delay", [False, True])
@pytest.mark.parametrize("lam", [5.0, 240.0, 900.0, 2400.0])
def test_frd_phase_margins_are_python_controls_to_the_bit(experiment, lam, delay):
    """The analysis' sampled phase margins (frd_phase_margins, without python-control's
    gain and stability margins) equal control.stability_margins(method="frd")'s."""
    import warnings

    import control

    from bwdesign.control.analysis import frd_phase_margins

    g = tuple(observer_gains(experiment, [-1500.0] * 3))
    lp = lin(experiment, lam, lam, g, dt=DT, form="discrete", integral_rate=lam / 2, delay=delay)
    sys = analyze_loop(lp).systems.loop
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        _, pms, _, _, wgc, _ = control.stability_margins(sys, returnall=True, method="frd")
    pm, wc = frd_phase_margins(sys)
    assert pm.size >= 1
    assert np.array_equal(pm, np.atleast_1d(pms)) and np.array_equal(wc, np.atleast_1d(wgc))


def test_a1_mismatch_state_feedback_vs_observer(experiment):
    """With true states an a1 error of -lambda1 lambda2/a1 removes the loop's stiffness;
    with the observer in the loop the x3 estimate absorbs it."""
    lo, _ = stability_interval(lin(experiment, 1.0, 2.0), estimator="state")
    assert lo == pytest.approx(-2.0 / experiment.a1, rel=0.01)
    lo_obs, hi_obs = stability_interval(lin(experiment, 1.0, 2.0, dt=DT))
    assert lo_obs < -0.2 and hi_obs > 1.0
    sw = mismatch_sweep(lin(experiment, 1.0, 2.0, dt=DT), deltas=[-0.05, 0.0, 0.05])
    assert sw.stable.all()
    assert np.allclose(sw.max_real_part, sw.max_real_part[1], rtol=0.01)
    sws = mismatch_sweep(lin(experiment, 1.0, 2.0, dt=DT), deltas=[-1e-3], estimator="state")
    assert not sws.stable[0]
    json.dumps(json_safe(sw.to_dict()))


def test_digital_tuning_is_kept_by_its_exact_arguments(experiment, monkeypatch):
    """The same arguments give the same tuning without computing it again; a copy goes
    out (changing it changes no later answer); other arguments are computed."""
    from bwdesign.design import tuning as T

    calls = []
    real_tune = T._tune

    def counted(*args):
        calls.append(args[1])
        return real_tune(*args)

    monkeypatch.setattr(T, "_MEMO", Memo(16))
    monkeypatch.setattr(T, "_tune", counted)
    a = digital_tuning(experiment, DT, integral_ratio=0.45)
    b = digital_tuning(experiment, DT, integral_ratio=0.45)
    assert len(calls) == 1 and a is not b
    assert (a.lambda1, a.gains, a.reasoning, a.worst_phase_margin) == (
        b.lambda1, b.gains, b.reasoning, b.worst_phase_margin
    )  # fmt: skip
    assert np.array_equal(a.nominal.poles, b.nominal.poles)
    b.candidates.clear()  # a caller's copy: the kept one is untouched
    c = digital_tuning(experiment, DT, integral_ratio=0.45)
    assert len(calls) == 1 and c.candidates == a.candidates and c.candidates
    d = digital_tuning(experiment, DT * (1 + 2**-52), integral_ratio=0.45)  # the next float
    assert len(calls) == 2 and d.dt != a.dt


def test_delay_lowers_phase_margin(experiment):
    g = tuple(observer_gains(experiment, [-1000.0] * 3))
    kw = dict(dt=DT, form="discrete")
    a0 = analyze_loop(lin(experiment, 500.0, 500.0, g, **kw))
    a1 = analyze_loop(lin(experiment, 500.0, 500.0, g, delay=True, compensate_delay=False, **kw))
    assert a1.phase_margin < a0.phase_margin


def test_digital_tuning(experiment):
    t = digital_tuning(experiment, DT, n_candidates=5)
    assert t.met and t.form == "discrete" and t.lambda1 == t.lambda2
    assert t.worst_gain_margin_db >= 6.0 and t.worst_phase_margin >= 45.0
    assert t.worst_delay_margin >= DT
    assert t.nominal.stable and t.nominal.delay
    assert 0.1 / DT <= t.observer_bandwidth <= 1.6 / DT  # searched
    fixed = digital_tuning(experiment, DT, observer_radius=0.2, n_candidates=3)
    assert fixed.observer_bandwidth == pytest.approx(0.2 / DT)  # a given radius is kept
    assert "the slowest observer (least sensor noise)" in t.reasoning
    assert set(t.controller_kwargs()) == {"gains", "lambda1", "lambda2", "form", "integral_rate"}
    json.dumps(json_safe(t.to_dict()))
    # the paper's observer gains cannot meet the requirements whatever lambda is
    assert not digital_tuning(experiment, DT, gains=PAPER_GAINS, n_candidates=5).met


def test_margin_requirements_are_one_object(experiment):
    """The three required margins travel together; the default is 6 dB, 45 deg, one sample."""
    assert MarginRequirements().as_dict(DT) == {
        "min_gain_margin_db": 6.0,
        "min_phase_margin": 45.0,
        "min_delay_margin": DT,
    }
    loose = MarginRequirements(gain_db=3, phase_deg=30.0, delay_samples=0.5)
    t = digital_tuning(experiment, DT, observer_radius=0.2, n_candidates=3, margins=loose)
    assert t.requirements == loose.as_dict(DT) and t.requirements["min_gain_margin_db"] == 3.0
    assert "min(GM/3 dB, PM/30 deg, DM/0.5 sample)" in t.reasoning
    with pytest.raises(InputError, match=r"margins.gain_db dB = -1 is outside"):
        MarginRequirements(gain_db=-1.0)
    with pytest.raises(InputError, match="margins must be a MarginRequirements"):
        digital_tuning(experiment, DT, margins={"gain_db": 6.0})


def test_observer_gains_place_poles(usable_plant):
    poles = [-900.0, -1000.0 + 300j, -1000.0 - 300j]
    l = observer_gains(usable_plant, poles)
    assert np.allclose(np.poly(np.linalg.eigvals(error_matrix(usable_plant, l))), np.poly(poles))


BAD = [
    ("discrete without dt", lambda p: lin(p, 1, 2, form="discrete"), "dt"),
    ("delay without dt", lambda p: analyze_loop(lin(p, 1, 2, delay=True)), "needs a sample time"),
    ("unknown form", lambda p: lin(p, 1, 2, form="zoh"), "form must be"),
    ("unknown estimator", lambda p: analyze_loop(lin(p, 1, 2), estimator="kalman"), "estimator"),
    ("negative dt", lambda p: lin(p, 1, 2, dt=-1.0), r"dt \(s\) = -1 is outside"),
    ("bad gains", lambda p: lin(p, 1, 2, (1.0, 2.0)), "3 gains|three numbers"),
    ("not a loop", lambda p: analyze_loop(p), "must be a ClosedLoop"),
    (
        "the PHDO",
        lambda p: analyze_loop(
            ClosedLoop(p, ObserverSpec.of("phdo", PAPER_GAINS), make_controller(p, 1, 2))
        ),
        "covers the PHSO and the ESO",
    ),
]


@pytest.mark.parametrize("label, make, match", BAD, ids=[b[0] for b in BAD])
def test_bad_inputs(experiment, label, make, match):
    with pytest.raises(ValueError, match=match):
        make(experiment)


def test_bad_sweep_and_poles(experiment):
    with pytest.raises(InputError, match="a1, a2, a3"):
        mismatch_sweep(lin(experiment, 1.0, 2.0), parameter="alpha")
    with pytest.raises(InputError, match="> -1"):
        mismatch_sweep(lin(experiment, 1.0, 2.0), deltas=[-1.5])
    with pytest.raises(InputError, match="negative real parts"):
        observer_gains(experiment, [-1.0, 2.0, -3.0])
    with pytest.raises(InputError, match="self-conjugate"):
        observer_gains(experiment, [-1.0, -2.0 + 1j, -3.0])
    with pytest.raises(InputError, match="observer_radius"):
        digital_tuning(experiment, DT, observer_radius=3.0)


@pytest.mark.parametrize("config", ["stack_actuator_800hz", "paper_simulation_corrected"])
def test_digital_tuning_lightly_damped_stages(config):
    """Resonant stages: searching the observer bandwidth meets the margins, and the
    chosen tuning tracks the config's reference stably with the computation delay."""
    from pathlib import Path

    from bwdesign.model.config import load_config

    c = load_config(Path(__file__).resolve().parents[1] / "configs" / f"{config}.toml")
    t = digital_tuning(c.plant, c.dt)
    assert t.met, t.reasoning
    assert t.worst_gain_margin_db >= 6.0 and t.worst_phase_margin >= 45.0
    assert t.worst_delay_margin >= c.dt
    # the observer must be faster than the lightly damped resonance
    assert t.observer_bandwidth > math.sqrt(c.plant.a1)
    period = 1.0 / c.reference.frequency
    lp = ClosedLoop.from_config(c, law=t, start=Start(), saturate=False).replace(delay=True)
    r = simulate(lp, c.reference, duration=3 * period)
    assert r.stable and r.status == "ok"
    amp = c.reference.amplitude
    assert np.max(np.abs(r.e[r.t > period])) < 0.01 * amp
    assert np.all(np.isfinite(r.u))


def test_digital_tuning_says_when_impossible():
    """A 2 kHz resonance at 0.2 ms: no stable candidate, and the result says so."""
    from bwdesign import preset

    t = digital_tuning(preset("paper_simulation_corrected"), 2e-4, n_candidates=3)
    assert not t.met
    assert "NOT met" in t.reasoning and "no candidate gives a loop stable" in t.reasoning
