"""The report's fast paths (issue 28) give the answers of the paths they replace.

Each shortcut is checked against the computation it stands for: the scalar refinement
against the array one (bit for bit), a search stopped at its question against the full
search, a synthesis probe that does not explain its "no" against one that does, the
sampled re-certification that keeps the continuous tiers against a full certify, and
the command line that builds one subcommand's options against the full parser.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bwdesign import certify, preset, synthesize
from bwdesign.certify.checks import scale_continuous
from bwdesign.certify.frequency import _w_scalar, continuous_family
from bwdesign.design.tiers import recertify_sampled
from bwdesign.observers.gains import error_matrix
from bwdesign.output.jsonenc import dump_json


def _w_array(G: np.ndarray, ah: float, bh: float) -> np.ndarray:
    """``wfun`` of ``RankOneFamily.inverse_envelope``, as the grid evaluates it."""
    S = (ah + bh) * G.real
    Q = ah * bh * np.abs(G) ** 2
    disc = np.sqrt(np.maximum(S * S - 4.0 * Q, 0.0))
    with np.errstate(all="ignore"):
        w_neg = (-S + disc) / 2.0
        w_pos = np.where(S + disc > 0, -2.0 * Q / (S + disc), 0.0)
    return np.maximum(np.where(S < 0, w_neg, w_pos), 0.0)


def test_the_scalar_refinement_is_the_array_one_bit_for_bit():
    rng = np.random.default_rng(28)
    special = [complex(1e150, 0.0), complex(math.nan, 1.0), complex(math.inf, 1.0), 0j]
    for i in range(20000):
        e = rng.uniform(-150, 150, 4)
        G = complex(rng.normal() * 10 ** e[0], rng.normal() * 10 ** e[1])
        if i < len(special):
            G = special[i]
        ah = min(0.0, float(rng.normal() * 10 ** (e[2] / 4))) if i % 3 else 0.0
        bh = abs(float(rng.normal() * 10 ** (e[3] / 4)))
        with np.errstate(all="ignore"):
            want = float(_w_array(np.array([G]), ah, bh)[0])
        got = _w_scalar(G, ah, bh)
        assert (got == want or (math.isnan(got) and math.isnan(want))) and math.copysign(
            1, got
        ) == math.copysign(1, want), (G, ah, bh, got, want)


@pytest.mark.parametrize("gains", [(8.0, 64.0, -512.0), (2286.2, 1208283.0, -6256.75)])
def test_a_search_stopped_at_its_question_answers_it_as_the_full_search(gains):
    p = preset("paper_experiment")
    sc = scale_continuous(p, error_matrix(p, gains))
    fam = continuous_family(sc.Ahat, sc.w)
    a, b = min(0.0, p.beta - abs(p.gamma)), p.beta + abs(p.gamma)
    for mu in (0.0, 10.0, 25.0):
        full = fam.inverse_envelope(a, b, mu)
        assert fam.inverse_envelope(a, b, mu, enough=lambda inv: False) == full
        for v in (1.0, 0.5 / full, 0.999 / full, 1.001 / full, 2.0 / full, 1e9):
            stopped = fam.inverse_envelope(a, b, mu, enough=lambda inv, v=v: not v < 1.0 / inv)
            assert (v < 1.0 / stopped) == (v < 1.0 / full)
            assert stopped <= full
        q_full = fam.min_q(-5.0, 80.0, mu)
        q_stop = fam.min_q(-5.0, 80.0, mu, enough=lambda q: q <= 0)
        assert (q_stop > 0) == (q_full > 0) and q_stop >= q_full


def test_a_probe_that_does_not_explain_its_no_has_the_same_answer():
    p = preset("paper_experiment")
    kw = {"decay": 100.0, "dt": 2e-4, "tier": "sector"}
    yes = synthesize(p, udot_max=5000.0, **kw)
    assert yes.feasible
    quiet_yes = synthesize(p, udot_max=5000.0, explain=False, **kw)
    assert dump_json(quiet_yes.to_dict()) == dump_json(yes.to_dict())
    no = synthesize(p, udot_max=2e6, **kw)
    quiet_no = synthesize(p, udot_max=2e6, explain=False, **kw)
    assert not no.feasible and not quiet_no.feasible
    assert no.binding != "unexplained" and quiet_no.binding == "unexplained"
    assert "not looked for" in quiet_no.reason and quiet_no.gains is None


def test_the_sampled_recertification_is_a_full_certify():
    p = preset("paper_experiment")
    res = synthesize(p, udot_max=400.0, decay=100.0)  # continuous: sector, no dt
    assert res.feasible and res.report.dt is None
    kept = recertify_sampled(res, 2e-4, False)
    full = certify(p, res.gains, udot_max=res.udot_max, decay=res.decay, dt=2e-4)
    assert dump_json(kept.report.to_dict()) == dump_json(full.to_dict())
    assert kept.discrete_gains == full.discrete_gains


def test_the_command_line_builds_the_options_of_the_command_it_names():
    from bwdesign.cli.main import COMMANDS, build_parser

    def options(parser, name):
        sub = next(a for a in parser._actions if a.dest == "command")
        return {o for a in sub.choices[name]._actions for o in a.option_strings}

    full = build_parser()
    only = build_parser(["report", "--config", "x.toml", "--out", "y"])
    assert options(only, "report") == options(full, "report") >= {"--no-cache", "--config"}
    assert options(only, "identify") == {"-h", "--help"}  # named, not built
    assert options(build_parser(["--version"]), "check") == {"-h", "--help"}
    names = {c[0] for c in COMMANDS}
    sub = next(a for a in build_parser([])._actions if a.dest == "command")
    assert set(sub.choices) == names
