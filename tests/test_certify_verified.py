"""Stated envelopes never above the exact one; a "no" only when no certificate passes (issue 24).

Item 1: near-marginal and lightly damped error poles, where the double-precision
frequency-domain estimate sat above the exact envelope (checked here against the
audit's independent mpmath criterion). Item 2: a lipschitz "no" where the exact
criterion holds, now certified by the KYP Riccati matrix.
"""

from __future__ import annotations

import importlib.util
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from bwdesign import BoucWenParams, certify, preset

ROOT = Path(__file__).resolve().parents[1]


def _audit():
    spec = importlib.util.spec_from_file_location(
        "certify_audit", ROOT / "analysis/certify_audit.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


AUDIT = _audit()


def _stage(a1, a2, beta, gamma):
    """a3 and alpha do not enter the observer error dynamics."""
    return BoucWenParams(a1=a1, a2=a2, a3=a1, alpha=1.0, beta=beta, gamma=gamma, name="t")


# (stage, gains, dt, damping of the pair): stated / exact on the unfixed code
NEAR_MARGINAL = {
    # sector 1.674x, sampled 1.661x (envelopes ~1e-10 V/s)
    "damping 1.1e-13": (
        _stage(32707.727466905155, 30.12982964019207, 0.4594652792251519, 0.5668935223598921),
        (17.738763912818754, -31394.32905156508, -2.704396617087682),
        1.0037463842181838e-06,
    ),
    # sector 2.144x, sampled 2.089x
    "damping 3.2e-16": (
        _stage(576218.8291313282, 193.69458474342244, 0.4083851431668226, 0.46407335333342054),
        (810.0392333781107, -244968.01577834837, -850.3257246464608),
        5.773070260714868e-06,
    ),
    # sector 1.054x, sampled 1.044x
    "damping 2.4e-10": (
        _stage(214103995.02985302, 602.7012215551172, 0.14151328601165078, 0.04537562788409454),
        (24272.661129500077, 100020164.60041772, -38195.72821670422),
        1.7860548695096754e-06,
    ),
    # sector 1.013x, sampled 1.018x
    "damping 1.1e-8": (
        _stage(27805.376515372154, 3.7025263446788195, 0.052378637498485155, 0.0032188973588665962),
        (774.3915632632309, 84570.85765600867, -3224.924270886218),
        4.126437204381642e-05,
    ),
    # sector 1.002x, sampled 1.002x: still stated, within 10 % of the exact envelope
    "damping 8.6e-8": (
        _stage(143899.93426569982, 129.7636416660964, 0.8289317725115392, 0.9393848687347933),
        (-51.443123561134016, -129855.159395188, -4.0109078306239585),
        6.333602100336757e-05,
    ),
}


def _exact(p, gains, K, dt):
    g = abs(p.gamma)
    c = abs(p.beta) + g
    return {
        "lipschitz": AUDIT.exact_continuous_envelope(p, gains, -c, c, 0.0),
        "sector": AUDIT.exact_continuous_envelope(
            p, gains, min(0.0, p.beta - g), max(0.0, p.beta + g), 0.0
        ),
        "sampled": AUDIT.exact_sampled(p, K, dt, 0.0),
    }


@pytest.mark.parametrize("name", list(NEAR_MARGINAL))
def test_near_marginal_envelopes_are_verified_or_refused(name):
    p, gains, dt = NEAR_MARGINAL[name]
    rep = certify(p, gains, udot_max=1e-14, dt=dt, allow_unbounded=True)
    exact = _exact(p, gains, np.asarray(rep.discrete_gains), dt)
    for cert in rep.certificates[1:]:
        assert cert.max_udot <= exact[cert.name], (name, cert.name)
        if cert.details["envelope_undecided"]:
            # refused: nothing above the verified request, with the reason and its number
            assert cert.max_udot <= cert.udot_max
            assert "double precision cannot decide" in cert.status
            assert f"conditioning {cert.details['envelope_conditioning']:.3g}" in cert.status
        else:
            assert cert.max_udot >= 0.49 * exact[cert.name]  # at most BACKOFF[-1] below
    if name == "damping 8.6e-8":  # lightly damped but well inside double precision
        for cert in rep.certificates[1:]:
            assert not cert.details["envelope_undecided"]
            assert 0.9 * exact[cert.name] < cert.max_udot <= exact[cert.name]
    if name in ("damping 1.1e-13", "damping 3.2e-16"):  # beyond what double precision decides
        assert all(c.details["envelope_undecided"] for c in rep.certificates[1:])


def test_a_pole_on_the_contour_in_double_precision_is_no_envelope_and_no_exception():
    """Audit case 55 (damping ~1e-17): the refinement landed exactly on a pole
    (ZeroDivisionError); now every tier states nothing, without a warning."""
    p = _stage(4114251.8432454253, 219.68070652306884, 0.13593633287979684, 0.1132345410964841)
    gains = (6250.649492709174, 58567945.56787978, -100737.4477262991)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rep = certify(p, gains, udot_max=1611.05, decay=1.8674e-14, dt=1.193038254539264e-06)
    assert not rep.certified and all(c.max_udot == 0.0 for c in rep.certificates)
    for cert in rep.certificates[1:3]:
        assert cert.details["envelope_undecided"] and "conditioning" in cert.status


def test_stated_decay_rates_hold_exactly():
    """The decay rate a tier states is re-checked exactly at (udot_max, rate)."""
    p, gains, dt = NEAR_MARGINAL["damping 8.6e-8"]
    rep = certify(p, gains, udot_max=1e-5, dt=dt, allow_unbounded=True)
    K = np.asarray(rep.discrete_gains)
    g = abs(p.gamma)
    held = 0
    for cert in rep.certificates[1:]:
        if cert.decay_rate is None:
            continue
        held += 1
        if cert.name == "sampled":
            assert AUDIT.exact_sampled(p, K, dt, cert.decay_rate, at=1e-5)
        else:
            lo, hi = (
                (-(abs(p.beta) + g), abs(p.beta) + g)
                if cert.name == "lipschitz"
                else (min(0.0, p.beta - g), max(0.0, p.beta + g))
            )
            assert AUDIT.exact_continuous_envelope(p, gains, lo, hi, cert.decay_rate, at=1e-5)
    assert held >= 2


def test_paper_envelopes_are_the_verified_ones():
    """Well-conditioned gains: the stated envelope is within 1e-5 below the estimate."""
    rep = certify(preset("paper_experiment"), (8.0, 64.0, -512.0), udot_max=360.9, dt=2e-4)
    for cert in rep.certificates[1:]:
        est = cert.details["envelope_estimate"]
        assert est * (1 - 1e-5) <= cert.max_udot <= est
        assert not cert.details["envelope_undecided"]
        assert cert.details["envelope_conditioning"] < 1e3


# -- item 2: a "no" where the exact criterion holds ----------------------------------

MISS = (
    _stage(1735661.1787522314, 998.4813304329405, 3.7722338989250503, 0.22948675519277925),
    (1298.0408860361285, 31034297.78221523, -45074.11159536974),
    9.517587164799275e-05,  # udot_max, 0.957 of the exact lipschitz envelope 9.946e-5 V/s
)


def test_lipschitz_miss_is_certified_by_the_riccati_matrix():
    """The unfixed code said 'the solver's P failed the outside check (the exact criterion
    holds...)'; the bounded-real Riccati P with a modal state weight passes that check."""
    p, gains, v = MISS
    c = abs(p.beta) + abs(p.gamma)
    exact = AUDIT.exact_continuous_envelope(p, gains, -c, c, 0.0)
    assert v < 0.96 * exact
    lip = certify(p, gains, udot_max=v, tiers=("lipschitz",), allow_unbounded=True).tier(
        "lipschitz"
    )
    assert lip.holds and lip.details["P_source"] == "kyp"
    assert all(m.passed for m in lip.margins)
    # the same P re-checked exactly (mpmath)
    assert AUDIT.exact_P_check(p, gains, lip, v, 0.0, None, None)
    assert lip.max_udot <= exact


def test_a_no_at_the_edge_of_double_precision_says_why():
    """So close to the envelope of a lightly damped pair that no P can pass the check: the
    "no" names the damping, the distance to the estimate and the check's margin."""
    p, gains, _ = MISS
    lip0 = certify(p, gains, udot_max=1e-12, tiers=("lipschitz",), allow_unbounded=True).tier(
        "lipschitz"
    )
    v = lip0.details["envelope_estimate"] * (1 - 2e-9)
    lip = certify(p, gains, udot_max=v, tiers=("lipschitz",), allow_unbounded=True).tier(
        "lipschitz"
    )
    assert not lip.holds
    assert f"relative damping to the decay line is {lip.details['pole_damping']:.2g}" in (
        lip.status
    )
    assert "the outside check requires" in lip.status
    assert math.isfinite(lip.max_udot) and lip.max_udot < v


# -- the audit's generator and verdict -----------------------------------------------


def test_audit_generates_near_marginal_and_beyond_double_gains():
    rng = np.random.default_rng(5)
    for pattern, (lo, hi) in AUDIT.DAMPING.items():
        lam = AUDIT.random_poles(rng, 400.0, pattern)
        pair = lam[np.argmax(np.abs(lam.imag))]
        assert 10**lo <= -pair.real / abs(pair) <= 10**hi
    assert AUDIT.DAMPING["beyond_double"][1] <= -14


def test_audit_fails_on_a_stated_envelope_above_exact():
    row = {
        "holds": False,
        "max_udot": 2.0,
        "decay_rate": None,
        "status": "",
        "undecided": False,
        "exact": 1.0,
        "false_hold": False,
        "miss": False,
        "env_rel_err": 1.0,
        "overstated": True,
        "decay_overstated": False,
    }
    case = {
        "case": 0,
        "pattern": "typical",
        "udot_max": 3.0,
        "K_rel_err": 0.0,
        "time": 0.0,
        "cpu_time": 0.0,
        "tiers": {t: dict(row, overstated=t == "sector") for t in AUDIT.TIERS_AUDITED},
    }
    summary = AUDIT.summarise([case], [])
    assert summary["failures"] == 1 and summary["tiers"]["sector"]["overstated"] == 1
    case["tiers"]["sector"]["overstated"] = False
    assert AUDIT.summarise([case], [])["failures"] == 0
