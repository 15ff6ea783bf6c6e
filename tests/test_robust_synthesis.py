"""Design against the uncertainty box: the tuning's corners and the certified robust design."""

from __future__ import annotations

import json
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from bwdesign import ClosedLoop, ObserverSpec, Sine, Start, UncertaintyBox, preset
from bwdesign.cli.main import main
from bwdesign.control.controllers import make_controller
from bwdesign.design.robust import RobustSearch, synthesize_robust
from bwdesign.design.tuning import digital_tuning
from bwdesign.errors import InputError, ParameterError
from bwdesign.sim.batch import simulate_batch

DT = 2e-4
REF = Sine(amplitude=80.0, offset=100.0, frequency=1.0)
UDOT = 80 * 2 * np.pi * 1.1


def _start(ctrl):
    """On the reference at t = 0, holding the law's feedforward input."""
    xd, vd, ad = (float(v[0]) for v in REF.evaluate(np.array([0.0])))
    u0 = float(ctrl.linear_gains()[1] @ np.array([xd, vd, ad]))
    return Start(x0=(xd, vd, 0.0), xhat0=(xd, vd, 0.0), u_prev=u0)


def _custom():
    # not a preset: more damping, a weaker hysteresis, its own name
    p = preset("paper_experiment")
    return p.replace(a2=1.5 * p.a2, alpha=0.8 * p.alpha, name="custom_stage")


def _box(**rel):
    return UncertaintyBox.from_dict({k: {"rel": v} for k, v in rel.items()})


def test_tuning_is_checked_at_every_linear_corner_of_the_box(paper_tuning):
    p = preset("paper_experiment")
    box = _box(a1=0.02, a2=0.05, a3=0.03, alpha=0.1)
    tu = digital_tuning(p, DT, uncertainty=box)
    assert tu.mismatch == pytest.approx({"a1": 0.02, "a2": 0.05, "a3": 0.03})
    assert "(8 corners)" in tu.reasoning
    # the worst margins are over the box's corners: never better than the nominal loop's
    assert tu.worst_gain_margin_db <= tu.nominal.gain_margin_db + 1e-9
    default = paper_tuning  # digital_tuning(p, DT)
    assert default.mismatch == {"a1": 0.02, "a3": 0.02}
    assert "(4 corners)" in default.reasoning


def test_tuning_refuses_two_mismatch_sources_and_an_undetermined_box():
    p = preset("paper_experiment")
    with pytest.raises(InputError, match="not both"):
        digital_tuning(p, DT, mismatch=0.02, uncertainty=_box(a1=0.02))
    box = UncertaintyBox.from_dict({"a1": {"rel": float("inf")}})
    with pytest.raises(ParameterError, match="a1 not determined"):
        digital_tuning(p, DT, uncertainty=box)
    with pytest.raises(InputError, match="UncertaintyBox"):
        digital_tuning(p, DT, uncertainty={"a1": 0.02})


def _worst_corner(params, box, design):
    ctrl = make_controller(
        params,
        design.lambda1,
        design.lambda2,
        form="discrete",
        dt=DT,
        integral_rate=design.integral_rate,
    )
    spec = ObserverSpec.of(design.observer, design.gains)
    loop = ClosedLoop(params, spec, ctrl, dt=DT, delay=design.delay, start=_start(ctrl))
    res = simulate_batch(loop, REF, box.vertices(params), duration=3.0)
    assert res.stable.all()
    return float(np.max(res.maxe))


@pytest.mark.slow
def test_robust_design_on_a_custom_stage_is_certified_and_covers_the_corners():
    p = _custom()
    box = _box(a1=0.02, a3=0.02, alpha=0.1)
    two = RobustSearch(max_candidates=2)
    d = synthesize_robust(p, dt=DT, uncertainty=box, udot_max=UDOT, reference=REF, search=two)
    assert d.feasible, d.reason
    assert d.observer == "phdo" and len(d.gains) == 4 and d.gains[2] == 0.0
    assert d.certificate.holds and d.certificate.n_vertices == 8
    held = [c for c in d.candidates if c["holds"]]
    # the design is the certified candidate of smallest bound
    assert d.certificate.tracking_bound == pytest.approx(min(c["tracking_bound"] for c in held))
    worst = _worst_corner(p, box, d)
    chosen = next(c for c in held if c["tracking_bound"] == d.certificate.tracking_bound)
    assert chosen["simulated_maxe"] == pytest.approx(worst, rel=1e-12)
    # the envelope the certificate assumes covers the simulated corners' input rate
    assert chosen["envelope"] >= chosen["simulated_udot_max"]
    rate = chosen["simulated_udot_max"]
    assert chosen["envelope"] == (UDOT if rate <= UDOT else 1.1 * rate)
    assert d.certificate.tracking_bound >= worst
    doc = d.to_dict()
    assert doc["certificate"]["holds"] is True and len(doc["candidates"]) == len(d.candidates)
    json.dumps(doc)


@pytest.mark.slow
def test_a_box_too_wide_has_no_robust_design_with_the_reason():
    p = _custom()
    d = synthesize_robust(
        p, dt=DT, uncertainty=_box(a3=0.95), udot_max=UDOT, reference=REF, search=RobustSearch(1)
    )
    assert not d.feasible and d.gains is None
    assert d.reason.startswith("no robust design")
    assert "not certified: no common Lyapunov function" in d.reason


def test_bad_arguments_are_typed_errors():
    p = preset("paper_experiment")
    with pytest.raises(InputError, match="UncertaintyBox"):
        synthesize_robust(p, dt=DT, uncertainty=None, udot_max=UDOT, reference=REF)
    with pytest.raises(InputError, match="max_candidates must be >= 1"):
        RobustSearch(max_candidates=0)
    with pytest.raises(InputError, match="max_candidates must be an integer"):
        RobustSearch(max_candidates=True)
    with pytest.raises(InputError, match="search must be a RobustSearch"):
        synthesize_robust(
            p, dt=DT, uncertainty=_box(a1=0.02), udot_max=UDOT, reference=REF, search={"n": 2}
        )


def _process(*argv):
    """``python -m bwdesign *argv`` in a new process."""
    return subprocess.run([sys.executable, "-m", "bwdesign", *argv], capture_output=True, text=True)


def _cli(capsys, *argv):
    """``bwdesign *argv`` in this process: its exit code and what it printed.

    As the bad-input tests run the commands (tests/test_bad_inputs.py); the entry point
    in a new process is test_cli_robust_needs_a_box_and_refuses_a_tier's first call and
    tests/test_cli.py. Saves ~1.4 s of imports per call.
    """
    capsys.readouterr()
    code = main(list(argv))
    out, err = capsys.readouterr()
    return SimpleNamespace(returncode=code, stdout=out, stderr=err)


def _stage_with_box(tmp_path, box_text):
    from bwdesign.model.stage_presets import stage_preset_path

    text = stage_preset_path("paper_experiment").read_text() + "\n[uncertainty]\n" + box_text
    f = tmp_path / "stage.toml"
    f.write_text(text)
    return f


@pytest.mark.slow
def test_cli_synthesize_robust(tmp_path, capsys):
    f = _stage_with_box(tmp_path, "a3 = { rel = 0.02 }\nalpha = { rel = 0.1 }\n")
    r = _cli(capsys, "synthesize", "--plant", str(f), "--robust", "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["robust_design"]["feasible"] is True
    assert doc["robust_design"]["certificate"]["n_vertices"] == 4
    r = _cli(capsys, "synthesize", "--plant", str(f), "--robust")
    assert r.returncode == 0 and "robust: yes" in r.stdout


def test_cli_robust_needs_a_box_and_refuses_a_tier(tmp_path, capsys):
    r = _process("synthesize", "--plant", "paper_experiment", "--robust", "--udot-max", "100")
    assert r.returncode == 2 and r.stderr.startswith("error:") and r.stderr.count("\n") == 1
    f = _stage_with_box(tmp_path, "")
    r = _cli(capsys, "synthesize", "--plant", str(f), "--robust")
    assert r.returncode == 2 and "[uncertainty]" in r.stderr
    f = _stage_with_box(tmp_path, "a3 = { rel = 0.02 }\n")
    r = _cli(capsys, "synthesize", "--plant", str(f), "--robust", "--tier", "sector")
    assert r.returncode == 2 and "--tier and --robust" in r.stderr
    r = _cli(
        capsys,
        "synthesize",
        "--plant",
        "paper_experiment",
        "--udot-max",
        "100",
        "--observer",
        "phdo",
    )
    assert r.returncode == 2 and "--observer applies to --robust only" in r.stderr
    r = _cli(
        capsys, "synthesize", "--plant", "paper_experiment", "--udot-max", "100", "--noise-max", "1"
    )
    assert r.returncode == 2 and "--noise-max applies to --robust only" in r.stderr
    r = _cli(capsys, "synthesize", "--plant", str(f), "--robust", "--decay", "0")
    assert r.returncode == 2 and "--decay does not apply to --robust" in r.stderr


def test_cli_synthesize_per_tier(capsys):
    r = _cli(
        capsys,
        "synthesize",
        "--plant",
        "paper_experiment",
        "--udot-max",
        "1e-3",
        "--tier",
        "theorem1",
    )
    assert r.returncode == 0, r.stderr
    assert "theorem1" in r.stdout and "feasible: yes" in r.stdout
    r = _cli(
        capsys,
        "synthesize",
        "--plant",
        "paper_experiment",
        "--udot-max",
        "100",
        "--tier",
        "sampled",
    )
    assert r.returncode == 2 and "dt" in r.stderr


def test_simulate_tuning_digital_is_chosen_against_the_files_box(tmp_path, capsys):
    f = _stage_with_box(tmp_path, "a1 = { rel = 0.03 }\na2 = { rel = 0.05 }\n")
    r = _cli(
        capsys, "simulate", "--plant", str(f), "--tuning", "digital", "--duration", "0.05", "--json"
    )
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    tuning = doc["tuning"]
    assert tuning["against"] == "[uncertainty]"
    assert tuning["mismatch"] == pytest.approx({"a1": 0.03, "a2": 0.05})


def test_phdo_robust_certificate_needs_the_tunings_split():
    p = preset("paper_experiment")
    from bwdesign import certify_robust

    with pytest.raises(InputError, match="l3 = 0"):
        ctrl = make_controller(p, 250.0, 250.0, form="discrete", dt=DT)
        spec = ObserverSpec.of("phdo", (786.2, 28982.94, -100.0, -682.09))
        loop = ClosedLoop(p, spec, ctrl, dt=DT)
        certify_robust(loop, uncertainty=_box(a3=0.02), udot_max=UDOT, reference=REF)
    with pytest.raises(InputError, match="observer"):
        synthesize_robust(
            p, dt=DT, uncertainty=_box(a3=0.02), udot_max=UDOT, reference=REF, observer="ukf"
        )


@pytest.mark.slow
def test_phdo_robust_loop_covers_brute_force_corners_on_a_custom_stage():
    from bwdesign import certify_robust
    from bwdesign.observers.gains import disturbance_gains_from

    p = _custom()
    box = _box(a1=0.02, a3=0.03, beta=0.1)
    gains = disturbance_gains_from((786.2, 28982.94, -782.0931942250238))
    loop = {"lambda1": 250.0, "lambda2": 250.0, "integral_rate": 125.0}
    ctrl = make_controller(p, form="discrete", dt=DT, **loop)
    cl = ClosedLoop(p, ObserverSpec("phdo", gains), ctrl, dt=DT, delay=True)
    rc = certify_robust(cl, uncertainty=box, udot_max=UDOT, reference=REF, interior_samples=4)
    assert rc.holds, rc.status
    rng = np.random.default_rng(3)
    plants = box.vertices(p) + box.sample(p, rng, 4)
    spec = ObserverSpec("phdo", gains)
    res = simulate_batch(
        ClosedLoop(p, spec, ctrl, dt=DT, delay=True, start=_start(ctrl)), REF, plants, duration=3.0
    )
    assert res.stable.all()
    assert rc.tracking_bound >= float(np.max(res.maxe))


@pytest.mark.slow
def test_a_phso_loop_that_chatters_at_a_corner_is_certified_only_at_the_rate_it_needs():
    # measured: with a1 high and a3 low the PHSO loop's input zig-zags at half the sample
    # rate (thousands of V/s), far outside the stage's envelope: its certificate must be
    # asked for that rate, not for the envelope the reference alone needs
    p = preset("paper_experiment")
    d = synthesize_robust(
        p,
        dt=DT,
        uncertainty=_box(a1=0.02, a3=0.02),
        udot_max=UDOT,
        reference=REF,
        observer="phso",
        search=RobustSearch(max_candidates=1),
    )
    (c,) = d.candidates
    assert c["simulated_udot_max"] > 3 * UDOT
    assert c["envelope"] == pytest.approx(1.1 * c["simulated_udot_max"])
    assert "envelope raised from" in c["status"]
    if c["holds"]:
        assert d.certificate.details["udot_max"] == c["envelope"]
        assert c["tracking_bound"] >= c["simulated_maxe"]


def test_a_design_with_sensor_noise_takes_its_envelope_from_the_noisy_corners():
    """With noise_max > 0 the corners are simulated with noise at that bound (+-noise_max,
    bounded noise): the certificate's envelope must cover the input rate noise causes,
    not the noise-free one (the audit: 3 694 V/s certified, 11 351 V/s reached)."""
    from bwdesign.sim.corners import simulate_corners

    p = _custom()
    box = _box(a1=0.02, a3=0.02)
    one = RobustSearch(max_candidates=1)
    kw = dict(dt=DT, uncertainty=box, udot_max=UDOT, reference=REF, search=one)
    noisy = synthesize_robust(p, noise_max=0.3, **kw).candidates[0]
    quiet = synthesize_robust(p, **kw).candidates[0]
    assert noisy["simulated_udot_max"] > quiet["simulated_udot_max"]
    assert noisy["envelope"] >= noisy["simulated_udot_max"]
    loop = ClosedLoop(
        p,
        ObserverSpec.of("phdo", noisy["gains"]),
        make_controller(
            p,
            noisy["lambda"],
            noisy["lambda"],
            form="discrete",
            dt=DT,
            integral_rate=noisy["integral_rate"],
        ),  # fmt: skip
        dt=DT,
        delay=True,
        compensate_delay=True,
    )
    rates = simulate_corners(loop.replace(start=_start(loop.controller)), box, REF, noise_max=0.3)
    assert noisy["simulated_udot_max"] == pytest.approx(float(np.max(rates.input_rate_max)))
