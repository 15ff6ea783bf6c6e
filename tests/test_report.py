"""The certified-gains report: content, determinism, atomic writing, bad configs."""

import json
import math
import re
from pathlib import Path

import pytest
from conftest import REPORT_DATE

from bwdesign.cli.main import main
from bwdesign.model.config import load_config
from bwdesign.output.jsonenc import dump_json
from bwdesign.report.certified import write_report
from bwdesign.study import CERTIFICATE_PARTS, REPORT_SECTIONS, study

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "paper_experiment.toml"
COMMITTED = ROOT / "reports" / "paper_experiment"
DATE = REPORT_DATE

#: Tolerance of the committed-JSON comparison. Gains, discrete gains and
#: decay rates come from deterministic solvers and closed forms and must agree
#: to 1e-6 relative; envelopes come from a bisection with 1 % resolution and
#: may move by one step (2 %) if a solver's last digits change.
RTOL_VALUES = 1e-6
RTOL_ENVELOPE = 0.02


@pytest.fixture
def built(paper_report):
    """The paper_experiment report (conftest: written once per run, read-only)."""
    return paper_report


def test_report_files_and_verdict(built):
    first = built
    out = first.out_dir
    for name in ("report.md", "report.html", "certificate.json"):
        assert (out / name).is_file()
    figures = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert len(figures) >= 5
    md = (out / "report.md").read_text()
    assert first.certified
    assert md.splitlines()[2].startswith("> **CERTIFIED")
    # the paper's gains and a synthesised set side by side, tier by tier
    assert "Configured gains l = (8, 64, -512)" in md
    for tier in ("theorem1", "lipschitz", "sector", "sampled"):
        assert f"| {tier} |" in md
    for fig in figures:
        assert f"figures/{fig}" in md
    assert "config sha256" in md and load_config(CONFIG).sha256 in md


def _md_row(md: str, first_cell: str) -> list[str]:
    line = next(ln for ln in md.splitlines() if ln.startswith(f"| {first_cell} |"))
    return [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]


def test_summary_block_quotes_the_report_numbers(built):
    """The summary at the top: verdict, envelope, loop error, export; the report's own numbers."""
    md, cert = built.md, built.cert
    lines = md.splitlines()
    top = lines.index("## Summary")
    assert top < lines.index("## Plant")
    items = ("verdict", "envelope", "tracking (recommended loop)", "export")
    rows = {r: _md_row(md, r)[1] for r in items}
    assert rows["verdict"].startswith("**CERTIFIED**: the configured gains (8, 64, -512)")
    assert f"{cert['configured']['best']}" in rows["verdict"]
    assert f"\\|u'\\| <= {cert['envelope']['udot_max']:.4g} V/s" in rows["envelope"]
    best = next(
        c for c in cert["configured"]["certificates"] if c["name"] == cert["configured"]["best"]
    )
    assert f"hold up to {best['max_udot']:.4g} V/s" in rows["envelope"]
    # the recommended loop's error is the tracking table's PHSO (digital tuning) row
    maxe = float(_md_row(md, "PHSO (digital tuning)")[1])
    assert f"with the PHSO: MAXE {maxe:.3g} um" in rows["tracking (recommended loop)"]
    eq12 = float(_md_row(md, "PHSO (eq. 12)")[1])
    assert (
        f"eq. 12 with the configured constants: MAXE {eq12:.3g} um"
        in rows["tracking (recommended loop)"]
    )
    cmd = "`bwdesign export-c --config paper_experiment.toml --out fw --tuning digital`"
    assert cmd in rows["export"]


def test_two_runs_are_identical(built, tmp_path):
    """A second report in this process, without a study cache, is the first (computed
    into an empty cache, conftest's paper_report) byte for byte, every file, the figures
    too (no state carried over; the cache changes nothing it computes)."""
    a = built
    b = write_report(load_config(CONFIG), tmp_path / "b", quiet=True, date=DATE)

    def tree(out):  # the reproducibility command names each run's own --out
        return {
            p.relative_to(out).as_posix(): p.read_bytes().replace(str(out).encode(), b"OUT")
            for p in sorted(out.rglob("*"))
            if p.is_file() and p.name != ".bwdesign-manifest.json"
        }

    one, two = tree(a.out_dir), tree(b.out_dir)
    assert sorted(one) == sorted(two) and any(k.startswith("figures/") for k in one)
    for name in one:
        assert one[name] == two[name], name


def test_the_reproducibility_command_writes_the_same_report(built):
    """It names the config and --out as given (issue 24: --out was missing)."""
    first = built
    md = first.md
    line = next(ln for ln in md.splitlines() if ln.startswith("| command |"))
    assert line == f"| command | bwdesign report --config {CONFIG} --out {first.out_dir} |"


def _compare(new, old, path=""):
    if isinstance(old, dict):
        if path == "":  # the report's own sections are checked by their tests
            old = {k: v for k, v in old.items() if k not in REPORT_SECTIONS}
        assert set(new) == set(old), path
        for k in old:
            if k in ("P", "margins", "solver", "status", "reason", "details"):
                continue
            _compare(new[k], old[k], f"{path}.{k}")
    elif isinstance(old, list):
        assert len(new) == len(old), path
        for i, (n, o) in enumerate(zip(new, old, strict=True)):
            _compare(n, o, f"{path}[{i}]")
    elif isinstance(old, float) and not isinstance(old, bool):
        rtol = RTOL_ENVELOPE if "max_udot" in path else RTOL_VALUES
        assert new == pytest.approx(old, rel=rtol, abs=1e-12), path
    else:
        assert new == old, path


def test_committed_certificate_json_is_current(built):
    """Regenerate certificate.json and compare with the committed one (tolerances above).

    The study of the certificate's parts alone also gives exactly the report's entries.
    """
    committed = json.loads((COMMITTED / "certificate.json").read_text())
    doc = study(load_config(CONFIG), parts=CERTIFICATE_PARTS).to_dict()
    fresh = json.loads(dump_json(doc))
    _compare(fresh, committed)
    report = {k: v for k, v in built.cert.items() if k not in REPORT_SECTIONS}
    assert fresh == report


def test_not_certified_is_a_well_formed_no(tmp_path, capsys):
    """Far above the paper gains' envelope nothing holds: report written, exit 1."""
    text = CONFIG.read_text().replace("from_reference = true\nmargin = 1.1", "udot_max = 1.0e5")
    cfg = tmp_path / "fast.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    code = main(["report", "--config", str(cfg), "--out", str(out), "--quiet"])
    assert code == 1
    md = (out / "report.md").read_text()
    assert md.splitlines()[2].startswith("> **NOT CERTIFIED")
    cert = json.loads((out / "certificate.json").read_text())
    assert cert["configured"]["certified"] is False
    assert cert["synthesis"]["feasible"] is True
    # the summary says no, and offers the gains that are certified at this envelope
    assert _md_row(md, "verdict")[1].startswith("**NOT CERTIFIED**: no tier certifies")
    export = _md_row(md, "export")[1]
    assert export.startswith("not the configured gains")
    gains = "(" + ", ".join(f"{g:.6g}" for g in cert["synthesis"]["gains"]) + ")"
    assert "`bwdesign export-c --config fast.toml --out fw --synthesize`" in export
    assert f"the synthesised gains {gains}, certified at" in export
    html = (out / "report.html").read_text()
    assert '<p id="verdict" class="verdict not-certified"' in html


GOOD = CONFIG.read_text()
BAD = [
    ("missing section", GOOD.replace("[sampling]\ndt = 0.0002", ""), "needs section(s) [sampling]"),
    (
        "unknown key",
        GOOD.replace("lambda2 = 2.0", "lambda2 = 2.0\nlambda3 = 1.0"),
        "unknown key(s) lambda3; allowed keys are lambda1, lambda2, u_max, u_min",
    ),
    ("wrong type", GOOD.replace("lambda1 = 1.0", 'lambda1 = "one"'), "lambda1 must be a number"),
    (
        "envelope not positive",
        GOOD.replace("from_reference = true\nmargin = 1.1", "udot_max = -5.0"),
        "[envelope] udot_max (input unit/s) = -5 is outside the supported range",
    ),
    (
        "envelope not a number",
        GOOD.replace("from_reference = true\nmargin = 1.1", 'udot_max = "fast"'),
        "must be a number",
    ),
]


@pytest.mark.parametrize("label, text, message", BAD, ids=[b[0] for b in BAD])
def test_bad_configs(tmp_path, capsys, label, text, message):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    code = main(["report", "--config", str(cfg), "--out", str(out), "--quiet"])
    _, err = capsys.readouterr()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("error: ") and message in err
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [cfg]  # no temporary directory left behind


def test_failure_leaves_existing_report_untouched(tmp_path, monkeypatch):
    from bwdesign.output.files import prepare_directory

    out = tmp_path / "out"
    with prepare_directory(out, command="report").stage() as stage:  # a previous report
        stage.write_text("report.md", "previous")
    import bwdesign.report.certified as report

    def boom(*a, **k):
        raise RuntimeError("simulated crash")

    monkeypatch.setattr(report, "build_report", boom)
    with pytest.raises(RuntimeError):
        write_report(load_config(CONFIG), out, quiet=True)
    assert (out / "report.md").read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


# -- synthesis per tier (issue 10, item 4) ---------------------------------------------


def _scaled_theorem1_envelope(params, gains, decay):
    """Corrected Theorem 1 in the norm ||S eps||, S = diag(1, 1/w0, 1), with the Lyapunov X.

    Independent of the synthesis: ``X`` solves ``X A^ + A^' X + 2 (decay/w0) X = -I`` for
    the scaled closed loop ``A^ = S A(l) S^-1 / w0``; then ``V' <= -(w0 - 2 L ||X||) |eps^|^2``.
    """
    import math

    import numpy as np
    from scipy.linalg import solve_continuous_lyapunov

    from bwdesign.observers.gains import error_matrix

    w0 = math.sqrt(params.a1)
    s = np.array([1.0, 1.0 / w0, 1.0])
    A = s[:, None] * error_matrix(params, gains) / s[None, :] / w0
    X = solve_continuous_lyapunov((A + decay / w0 * np.eye(3)).T, -np.eye(3))
    assert np.linalg.eigvalsh(X).min() > 0
    return w0 / (2 * (abs(params.beta) + abs(params.gamma)) * np.linalg.eigvalsh(X).max())


def test_tier_synthesis_rows_hold_when_recomputed(built):
    """Each row's gains hold below its envelope and fail above it (certify, not the LMI)."""
    from bwdesign.certify.tiers import certify
    from bwdesign.design.gains import synthesize

    first = built
    cert, md = first.cert, first.md
    config = load_config(CONFIG)
    p, dt = config.plant, config.dt
    ts = cert["tier_synthesis"]
    v = cert["envelope"]["udot_max"]
    assert ts["udot_max"] == v and ts["decay"] == 100.0  # no [synthesis]: DEFAULT_DECAY
    rows = {r["tier"]: r for r in ts["tiers"]}
    assert list(rows) == ["theorem1", "lipschitz", "sector", "sampled"]
    for tier, r in rows.items():
        assert r["gains"] is not None, tier
        E = math.inf if r["envelope_unbounded"] else r["envelope"]
        cell = "unbounded" if math.isinf(E) else f"{E:.4g}"
        assert re.search(rf"\| {tier} \| [^|]+ \| \([^|]+\) \| {re.escape(cell)} \|", md), tier
        if tier == "theorem1":
            lyap = _scaled_theorem1_envelope(p, r["gains"], r["decay"])
            assert 0 < E <= lyap * (1 + 1e-9)  # the Lyapunov X proves at least the envelope
            assert r["feasible"] is (v < E) and not r["feasible"]  # 100 V/s < 397 V/s
            assert lyap < v  # honest "no": not even the best X for these gains reaches v
            continue
        below = 1e3 * v if math.isinf(E) else 0.98 * E
        rep = certify(p, r["gains"], udot_max=below, decay=r["decay"], dt=dt, tiers=(tier,))
        assert rep.tier(tier).holds, tier
        if math.isfinite(E):
            rep = certify(p, r["gains"], udot_max=1.03 * E, decay=r["decay"], dt=dt, tiers=(tier,))
            assert not rep.tier(tier).holds, tier
        assert r["feasible"] and r["requested_udot_max"] >= v
    # the search over the requested rate is what makes the sector row large
    at_v = synthesize(p, udot_max=v, decay=100.0, dt=dt, tier="sector")
    assert rows["sector"]["searched"] and rows["sector"]["syntheses"] > 2
    assert rows["sector"]["envelope"] > 10 * at_v.report.tier("sector").max_udot


def test_tier_search_brackets_the_feasibility_edge():
    """The search over the requested rate stops within SEARCH_RTOL of a feasibility edge."""
    from types import SimpleNamespace

    from bwdesign.study.tiers import SEARCH_RTOL, search_requested_rate

    for edge, start in ((1234.5, 10.0), (3.0, 10.0)):
        calls = []

        def run(u, edge=edge, calls=calls):
            calls.append(u)
            return SimpleNamespace(feasible=u <= edge)

        tried = search_requested_rate(run, start, start <= edge)
        ok = [u for u, res in tried if res.feasible] + ([start] if start <= edge else [])
        bad = [u for u, res in tried if not res.feasible] + ([] if start <= edge else [start])
        assert max(ok) <= edge < min(bad) <= max(ok) * (1 + SEARCH_RTOL)
        assert calls == [u for u, _ in tried] and len(calls) < 20


def test_batch_estimation_maxe_is_the_scalar_runs_max_error():
    """The robust table's simulated column: simulate_batch's steady-state max |xhat - x|."""
    import numpy as np

    from bwdesign import ClosedLoop, ObserverSpec, preset, simulate
    from bwdesign.control.controllers import make_controller
    from bwdesign.model.references import Sine
    from bwdesign.sim.batch import simulate_batch

    p = preset("paper_experiment")
    corners = [p.replace(a1=1.02 * p.a1, alpha=0.9 * p.alpha), p.replace(a3=0.98 * p.a3)]
    ref = Sine(amplitude=80.0, offset=100.0, frequency=5.0)
    ctrl = make_controller(p, 250.0, 250.0, form="discrete", dt=2e-4, integral_rate=125.0)
    loop = ClosedLoop(p, ObserverSpec.of("phso", (786.2, 28982.94, -782.09)), ctrl, dt=2e-4)
    batch = simulate_batch(loop, ref, corners, duration=0.6, noise_std=0.05, seeds=[3, 4])
    assert batch.estimation_maxe.shape == (2, 3)
    assert np.all(batch.estimation_maxe >= batch.estimation_rmse)
    for i, tp in enumerate(corners):
        r = simulate(loop, ref, duration=0.6, true_params=tp, noise_std=0.05, seed=[3, 4][i])
        t = np.asarray(r.t)
        sel = (t >= batch.window[0] - 1e-12) & (t <= batch.window[1] + 1e-12)
        err = np.abs(np.asarray(r.xhat) - np.asarray(r.x))[sel].max(axis=0)
        assert batch.estimation_maxe[i] == pytest.approx(err, rel=1e-9)
        assert batch.maxe[i] == pytest.approx(r.metrics.maxe, rel=1e-9)


def test_tier_rows_when_synthesis_says_no(monkeypatch):
    """theorem1 below the stage's rate: gains fetched at half its envelope; no design: no gains."""
    from types import SimpleNamespace

    import bwdesign.study.tiers as tiers
    from bwdesign import preset

    calls = []

    def fake(params, *, udot_max, decay, pole_radius, dt, allow_unbounded, tier, explain=True):
        calls.append((tier, udot_max))
        edge = {"theorem1": 100.0, "lipschitz": 0.0, "sector": 50.0}[tier]
        ok = udot_max < edge
        # gains asked for a larger rate reach a larger envelope
        rep = SimpleNamespace(tier=lambda name: SimpleNamespace(max_udot=edge + udot_max))
        return SimpleNamespace(
            feasible=ok,
            gains=(1.0, 2.0, 3.0) if ok else None,
            discrete_gains=None,
            max_udot=edge,
            report=rep if ok else None,
            reason=f"{tier} at {udot_max:g}: {'yes' if ok else 'no'}",
        )

    monkeypatch.setattr(tiers, "synthesize", fake)
    rows = {
        r.tier: r
        for r in tiers.synthesize_per_tier(preset("paper_experiment"), udot_max=400.0, decay=10.0)
    }
    assert list(rows) == ["theorem1", "lipschitz", "sector"]  # no dt: no sampled tier
    t1 = rows["theorem1"]
    assert calls[:2] == [("theorem1", 400.0), ("theorem1", 50.0)]
    assert not t1.feasible and t1.gains == (1.0, 2.0, 3.0) and t1.envelope == 100.0
    assert t1.requested == 50.0 and t1.syntheses == 2 and t1.theorem1_unscaled == 150.0
    lip = rows["lipschitz"]
    assert lip.gains is None and lip.envelope == 0.0 and lip.requested is None
    assert lip.reason == "lipschitz at 400: no" and lip.syntheses == 1
    sec = rows["sector"]  # infeasible at 400: searched downwards, 25 is feasible
    assert sec.searched and not sec.feasible
    assert 50.0 / (1 + tiers.SEARCH_RTOL) <= sec.requested < 50.0  # the bisection's edge
    assert sec.envelope == 50.0 + sec.requested  # the best of the feasible syntheses
    assert sec.to_dict()["envelope_unbounded"] is False


def test_the_nominal_certificate_says_what_its_bound_is_made_of(built):
    """A stage without [uncertainty]: the nominal section names the parts of each bound,
    the certificate.json's ``tracking_bound_parts`` (paper_experiment: the jump)."""
    md, cert = built.md, built.cert
    for rl in cert["robust"]["nominal"].values():
        parts = rl["certificate"]["details"]["tracking_bound_parts"]
        total = sum(parts.values())
        assert total == pytest.approx(rl["tracking_bound"], rel=1e-9)
        top = max(parts, key=parts.get)
        assert top == "hysteresis jump"
        assert f"{rl['observer'].upper()} (nominal): {top} {100 * parts[top] / total:.1f} %" in md
