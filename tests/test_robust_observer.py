"""Robust certificate of the sampled observer error over an uncertainty box (issue 10, item 3)."""

from __future__ import annotations

import numpy as np
import pytest

from bwdesign import (
    BoxSampling,
    HysteresisObserver,
    UncertaintyBox,
    certify_robust_observer,
    certify_robust_observer_discrete,
    preset,
    synthesize_robust_observer,
)
from bwdesign.certify.checks import rho_interval
from bwdesign.errors import GainError, InputError, ParameterError
from bwdesign.model.plant import discretize, hysteresis_increment, zoh_step
from bwdesign.observers.gains import discrete_gains

DT = 2e-4
GAINS = (786.2, 28982.94, -782.0931942250238)  # the paper stage's digital tuning
UDOT = 80 * 2 * np.pi * 1.1
RANGE = (0.0, 150.0)
SMALL = {"a1": {"rel": 0.02}, "a3": {"rel": 0.02}, "alpha": {"rel": 0.1}}
PAPER_BOX = {k: {"rel": 0.02} for k in ("a1", "a2", "a3")} | {
    k: {"rel": 0.1} for k in ("alpha", "beta", "gamma")
}


def _custom():
    # not a preset: the paper stage with more damping, a weaker hysteresis and its own name
    p = preset("paper_experiment")
    return p.replace(a2=1.5 * p.a2, alpha=0.8 * p.alpha, name="custom_stage")


def _inputs(rng, n, lo, hi, udot, dt):
    """Admissible input: piecewise-constant rates |u'| <= udot, reflected inside [lo, hi]."""
    u = np.empty(n)
    u[0] = rng.uniform(lo, hi)
    k, rate = 0, 0.0
    for i in range(1, n):
        if i >= k:
            rate = rng.choice([-1.0, 1.0]) * udot * rng.uniform(0.3, 1.0)
            k = i + int(rng.integers(20, 400))
        v = u[i - 1] + rate * dt
        if not lo <= v <= hi:
            rate = -rate
            v = u[i - 1] + rate * dt
        u[i] = v
    return u


def _run(model, plant, u, *, K=None, gains=GAINS, noise=None, check_recursion=False):
    """Observer (model) beside the true plant from rest; max |e1|, |e3| of the posterior."""
    x = np.array([plant.a3 * u[0] / plant.a1, 0.0, 0.0])  # equilibrium of u[0], x3 = 0
    kw = {"discrete": K} if K is not None else {"gains": gains}
    obs = HysteresisObserver(model, dt=DT, x0=x.copy(), u_prev=u[0], **kw)
    zm, zv = discretize(model, DT), discretize(plant, DT)
    Fm, gm, Fv, gv = (np.asarray(v) for v in (zm.F, zm.g, zv.F, zv.g))
    G = np.eye(3) - np.outer(obs.K, [1.0, 0.0, 0.0])
    rho_lo, rho_hi = rho_interval(model, UDOT, DT)
    worst = np.zeros(3)
    u_prev = u[0]
    e = np.zeros(3)
    for k, uk in enumerate(u):
        n = 0.0 if noise is None else noise[k]
        xhat = obs.x.copy()
        xn = zoh_step(plant, x, u_prev, uk, DT)
        if check_recursion:
            hm_hat = hysteresis_increment(model, xhat[2], u_prev, uk)
            hm = hysteresis_increment(model, x[2], u_prev, uk)
            hv = hysteresis_increment(plant, x[2], u_prev, uk)
            if abs(e[2]) > 1e-6:
                rho = (hm_hat - hm) / e[2]
                assert rho_lo - 1e-9 <= rho <= rho_hi + 1e-9
            De = np.array([e[0], e[1], hm_hat - hm])
            w = np.array([x[0], x[1], hv])
            pred = G @ (Fm @ De + Fm[:, 2] * (hm - hv) + (Fm - Fv) @ w + (gm - gv) * uk)
            pred = pred + obs.K * n
        obs.predict(uk)
        obs.update(xn[0] + n)
        e = obs.x - xn
        if check_recursion:
            assert np.all(np.abs(pred - e) <= 1e-9 * (1 + np.abs(xn))), (k, pred, e)
        worst = np.maximum(worst, np.abs(e))
        x, u_prev = xn, uk
    return worst


def _brute(model, box, *, n_interior=2, seconds=1.0, noise_max=0.0, seed=1, **kw):
    rng = np.random.default_rng(seed)
    plants = box.vertices(model) + box.sample(model, rng, n_interior)
    n = int(seconds / DT)
    worst = np.zeros(3)
    for tp in plants:
        u = _inputs(rng, n, *RANGE, UDOT, DT)
        noise = rng.uniform(-noise_max, noise_max, n) if noise_max else None
        worst = np.maximum(worst, _run(model, tp, u, noise=noise, **kw))
    return worst


def _cert(p, box, **kw):
    kw = {"sampling": BoxSampling(2), "input_range": RANGE} | kw
    return certify_robust_observer(
        p, GAINS, dt=DT, uncertainty=UncertaintyBox.from_dict(box), udot_max=UDOT, **kw
    )


def test_error_recursion_matches_the_observer_beside_a_true_plant():
    p = _custom()
    box = UncertaintyBox.from_dict(PAPER_BOX)
    rng = np.random.default_rng(3)
    for tp in box.vertices(p)[::21] + box.sample(p, rng, 1):
        u = _inputs(rng, 1500, *RANGE, UDOT, DT)
        _run(p, tp, u, noise=rng.uniform(-0.05, 0.05, u.size), check_recursion=True)


def test_bound_covers_brute_force_corners_and_interior_on_a_custom_stage():
    p = _custom()
    rc = _cert(p, SMALL)
    assert rc.holds, rc.status
    assert rc.n_vertices == 8 and rc.n_interior == 2
    assert all(m.passed for m in rc.margins)
    sim = _brute(p, UncertaintyBox.from_dict(SMALL))
    assert rc.estimation_bound >= sim[0] > 0
    assert rc.x3_estimation_bound >= sim[2] > 0
    # conservative, not vacuous
    assert rc.estimation_bound / sim[0] < 100
    assert rc.x3_estimation_bound / sim[2] < 100


def test_noise_enters_the_bound_and_the_brute_force_stays_below():
    p = _custom()
    box = {"a3": {"rel": 0.02}}
    quiet = _cert(p, box, a=0.97)
    noisy = _cert(p, box, a=0.97, noise_max=0.1)
    assert quiet.holds and noisy.holds
    assert noisy.estimation_bound > quiet.estimation_bound
    assert noisy.input_bounds["noise"] == 0.1
    sim = _brute(p, UncertaintyBox.from_dict(box), noise_max=0.1, n_interior=0, seconds=0.5)
    assert noisy.estimation_bound >= sim[0]
    assert noisy.x3_estimation_bound >= sim[2]


def test_the_bound_grows_with_the_box():
    p = preset("paper_experiment")
    narrow = _cert(p, {"a3": {"rel": 0.02}}, sampling=BoxSampling(0))
    wide = _cert(p, {"a3": {"rel": 0.6}}, sampling=BoxSampling(0))
    assert narrow.holds and wide.holds
    assert wide.input_bounds["m2"] == pytest.approx(30 * narrow.input_bounds["m2"], rel=1e-6)
    assert wide.estimation_bound > 10 * narrow.estimation_bound


def test_a_box_too_wide_is_not_certified_with_the_reason():
    # beta -95 % leaves the bounded class at a corner (beta - gamma < 0 there): no h_max
    p = preset("paper_experiment")
    rc = _cert(p, {"beta": {"rel": 0.95}, "a3": {"rel": 0.6}})
    assert not rc.holds and rc.estimation_bound is None
    assert "box is too wide" in rc.status and "bounded class" in rc.status
    res = synthesize_robust_observer(
        p, dt=DT, uncertainty=UncertaintyBox.from_dict({"beta": {"rel": 0.95}}), udot_max=UDOT,
        input_range=RANGE,
    )  # fmt: skip
    assert not res.feasible and "box is too wide" in res.reason


def test_an_input_rate_too_high_is_not_certified_with_the_reason():
    p = preset("paper_experiment")
    box = UncertaintyBox.from_dict({"a3": {"rel": 0.02}, "alpha": {"rel": 0.1}})
    for udot, why in ((1e6, "no common Lyapunov function"), (1e7, "input bound is infinite")):
        rc = certify_robust_observer(
            p, GAINS, dt=DT, uncertainty=box, udot_max=udot, input_range=RANGE,
            sampling=BoxSampling(0),
        )  # fmt: skip
        assert not rc.holds and rc.estimation_bound is None
        assert rc.status.startswith("not certified") and why in rc.status


def test_solver_trouble_is_never_a_certificate(monkeypatch):
    from bwdesign.certify import lmi

    def broken(*args, **kwargs):
        return lmi.LMISolution(ok=False, status="solver_error", solver="CLARABEL", objective=None)

    monkeypatch.setattr(lmi, "robust_ellipsoid", broken)
    rc = _cert(_custom(), {"a3": {"rel": 0.02}}, a=0.97)
    assert not rc.holds and rc.estimation_bound is None and rc.x3_estimation_bound is None
    assert "solver_error" in rc.status


def test_a_failing_outside_check_is_not_a_certificate(monkeypatch):
    from bwdesign.certify import lmi

    real = lmi.robust_ellipsoid

    def shrunk(*args, **kwargs):
        sol = real(*args, **kwargs)
        values = {"Q": 0.5 * np.asarray(sol["Q"]), "lam": np.asarray(sol["lam"])}
        return lmi.LMISolution(True, sol.status, sol.solver, sol.objective, values)

    monkeypatch.setattr(lmi, "robust_ellipsoid", shrunk)
    rc = _cert(_custom(), {"a3": {"rel": 0.02}}, a=0.97)
    assert not rc.holds and rc.estimation_bound is None
    assert "outside check" in rc.status


def test_bad_input_is_refused():
    p = preset("paper_experiment")
    with pytest.raises(InputError, match="input_range"):
        _cert(p, SMALL, input_range=(1.0, 1.0))
    with pytest.raises(ParameterError, match="a1 not determined"):
        _cert(p, {"a1": {"rel": float("inf")}})
    with pytest.raises(GainError):
        certify_robust_observer(
            p, None, dt=DT, uncertainty=UncertaintyBox.from_dict(SMALL), udot_max=UDOT,
            input_range=RANGE,
        )  # fmt: skip
    with pytest.raises(GainError, match="discrete gains K"):
        certify_robust_observer_discrete(
            p, (1.0, 2.0), dt=DT, uncertainty=UncertaintyBox.from_dict(SMALL), udot_max=UDOT,
            input_range=RANGE,
        )  # fmt: skip


def test_the_discrete_gain_certifies_as_its_continuous_gains_do():
    p = _custom()
    box = UncertaintyBox.from_dict({"a3": {"rel": 0.02}})
    kw = dict(dt=DT, uncertainty=box, udot_max=UDOT, input_range=RANGE, sampling=BoxSampling(2))
    given = certify_robust_observer(p, GAINS, a=0.97, **kw)
    K = discrete_gains(p, GAINS, DT)
    direct = certify_robust_observer_discrete(p, K, a=0.97, **kw)
    assert given.holds and direct.holds
    assert direct.estimation_bound == given.estimation_bound


@pytest.mark.parametrize("target", ["x3", "x1"])
def test_synthesis_beats_the_given_gains_and_is_recertified(target):
    p = _custom()
    box = UncertaintyBox.from_dict(SMALL)
    kw = {"dt": DT, "uncertainty": box, "udot_max": UDOT, "input_range": RANGE, "noise_max": 0.05}
    given = certify_robust_observer(p, GAINS, sampling=BoxSampling(2), **kw)
    res = synthesize_robust_observer(p, target=target, sampling=BoxSampling(2), **kw)
    assert res.feasible, res.reason
    cert = res.certificate
    assert cert.holds and cert.details["K"] == pytest.approx(list(res.discrete_gains))
    mine = cert.x3_estimation_bound if target == "x3" else cert.estimation_bound
    theirs = given.x3_estimation_bound if target == "x3" else given.estimation_bound
    assert mine <= theirs
    assert mine <= res.lmi_bound * 1.01  # the same P is feasible there (up to eps, rounding)
    # the synthesised gains keep their promise beside the true plants
    sim = _brute(p, box, n_interior=0, seconds=0.5, noise_max=0.05, K=res.discrete_gains)
    assert mine >= sim[2 if target == "x3" else 0]


def test_synthesis_with_a_pole_disk_has_a_continuous_equivalent():
    p = preset("paper_experiment")
    res = synthesize_robust_observer(
        p, dt=DT, uncertainty=UncertaintyBox.from_dict(SMALL), udot_max=UDOT,
        input_range=RANGE, noise_max=0.05, pole_radius=2000.0, sampling=BoxSampling(0),
    )  # fmt: skip
    assert res.feasible, res.reason
    assert res.gains is not None
    z = np.linalg.eigvals(
        (np.eye(3) - np.outer(res.discrete_gains, [1, 0, 0])) @ discretize(p, DT).F
    )
    assert np.max(np.abs(z - 1)) < -np.expm1(-2000.0 * DT)


def test_synthesis_solver_trouble_is_infeasible(monkeypatch):
    from bwdesign.certify import lmi

    def broken(*args, **kwargs):
        return lmi.LMISolution(ok=False, status="solver_error", solver="CLARABEL", objective=None)

    monkeypatch.setattr(lmi, "robust_observer_synthesis", broken)
    res = synthesize_robust_observer(
        _custom(), dt=DT, uncertainty=UncertaintyBox.from_dict(SMALL), udot_max=UDOT,
        input_range=RANGE, sampling=BoxSampling(0),
    )  # fmt: skip
    assert not res.feasible and res.certificate is None and res.gains is None
    assert "solver_error" in res.reason


@pytest.mark.slow
def test_paper_experiment_64_corners_against_brute_force():
    p = preset("paper_experiment")
    rc = _cert(p, PAPER_BOX, sampling=BoxSampling(8))
    assert rc.holds, rc.status
    assert rc.n_vertices == 64
    sim = _brute(p, UncertaintyBox.from_dict(PAPER_BOX), n_interior=4, seconds=0.6)
    assert rc.estimation_bound >= sim[0]
    assert rc.x3_estimation_bound >= sim[2]


def test_certify_keyword_adds_the_robust_certificate():
    from bwdesign import certify

    p = _custom()
    box = UncertaintyBox.from_dict({"a3": {"rel": 0.02}})
    kw = {"udot_max": UDOT, "dt": DT}
    plain = certify(p, GAINS, **kw)
    assert plain.robust is None and "robust" not in plain.to_dict()
    rep = certify(p, GAINS, uncertainty=box, input_range=RANGE, noise_max=0.01, **kw)
    direct = certify_robust_observer(
        p, GAINS, uncertainty=box, input_range=RANGE, noise_max=0.01, **kw
    )
    assert rep.robust.holds and rep.robust.estimation_bound == direct.estimation_bound
    assert rep.to_dict()["robust"]["x3_estimation_bound"] == direct.x3_estimation_bound
    with pytest.raises(InputError, match="input range"):
        certify(p, GAINS, uncertainty=box, **kw)
    with pytest.raises(InputError, match="sample time"):
        certify(p, GAINS, udot_max=UDOT, uncertainty=box, input_range=RANGE)
    with pytest.raises(ParameterError, match="alpha not determined"):
        certify(
            p, GAINS, uncertainty=UncertaintyBox.from_dict({"alpha": {"abs": float("inf")}}),
            input_range=RANGE, **kw,
        )  # fmt: skip


def _stage_file(tmp_path, extra):
    text = (
        '[plant]\nname = "custom_stage"\na1 = 159827.5\na2 = 1070.7\na3 = 222665.02\n'
        "alpha = 0.3836\nbeta = 0.3762\ngamma = 0.0378\n"
        f"[observer]\ngains = {list(GAINS)}\n[sampling]\ndt = {DT}\n"
        f"[envelope]\nudot_max = {UDOT}\n" + extra
    )
    path = tmp_path / "stage.toml"
    path.write_text(text)
    return str(path)


def test_cli_runs_the_robust_certificate(tmp_path, capsys):
    import json

    from bwdesign.cli.main import main

    box = "[uncertainty]\na3 = { rel = 0.02 }\n"
    f = _stage_file(tmp_path, '[controller]\nlambda1 = 250.0\nlambda2 = 250.0\n'
                    'u_min = 0.0\nu_max = 150.0\n' + box)  # fmt: skip
    assert main(["certify", "--plant", f, "--json", "--noise-max", "0.01"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rob = doc["robust"]
    assert rob["holds"] and rob["input_range"] == [0.0, 150.0] and rob["noise_max"] == 0.01
    assert doc["defaults_from_file"]["options"]["--input-range"] == "[controller]"
    # without limits or reference the range must be given; a bad one is exit 2
    g = _stage_file(tmp_path, box)
    assert main(["certify", "--plant", g]) == 2
    assert "--input-range" in capsys.readouterr().err
    assert main(["certify", "--plant", g, "--input-range", "5,1"]) == 2
    assert main(["certify", "--plant", g, "--input-range", "0,150"]) == 0
    out = capsys.readouterr().out
    assert "robust observer over [uncertainty]" in out and "holds: yes" in out
    # a box too wide: the tiers hold, the robust certificate does not -> exit 1
    wide = _stage_file(tmp_path, "[uncertainty]\nbeta = { rel = 0.95 }\n")
    assert main(["certify", "--plant", wide, "--input-range", "0,150"]) == 1
    assert "box is too wide" in capsys.readouterr().out
    # robust options without a box are a usage error
    assert main(["certify", "--plant", "paper_experiment", "--gains", "8,64,-512",
                 "--udot-max", "100", "--noise-max", "0.1"]) == 2  # fmt: skip


def test_cli_uncertainty_from_another_file(tmp_path, capsys):
    from bwdesign.cli.main import main

    f = _stage_file(tmp_path, "[uncertainty]\na3 = { rel = 0.02 }\n")
    base = ["certify", "--plant", "paper_experiment", "--gains", ",".join(map(str, GAINS)),
            "--udot-max", str(UDOT), "--dt", str(DT)]  # fmt: skip
    assert main([*base, "--uncertainty-from", f, "--input-range", "0,150"]) == 0
    assert "holds: yes" in capsys.readouterr().out
    assert main([*base, "--uncertainty-from", f]) == 2  # no range for a preset
    assert main([*base, "--uncertainty-from", str(tmp_path / "missing.toml")]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 2 and "Traceback" not in err
