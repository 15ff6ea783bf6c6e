"""Certificates for the PHDO's lumped error: verdicts, the outside re-check, brute force."""

from __future__ import annotations

import numpy as np
import pytest

from bwdesign import DisturbanceHysteresisObserver, certify_disturbance, preset, simulate_zoh
from bwdesign.certify import verify_disturbance
from bwdesign.certify.disturbance import _problem
from bwdesign.errors import GainError, InputError

P0 = preset("paper_experiment")
DT = 2e-4
G = (786.2, 28982.94, 0.0, -782.0932)  # the digital tuning's PHDO gains at 0.2 ms
G_SPLIT = (786.2, 28982.94, -234.6, -547.5)  # l3 != 0: the split is not trivial


@pytest.mark.parametrize("gains", [G, G_SPLIT])
@pytest.mark.parametrize("dt", [None, DT])
def test_certified_and_rechecked(gains, dt):
    c = certify_disturbance(P0, gains, udot_max=400.0, dt=dt)
    assert c.holds, c.status
    assert c.tier == ("sampled" if dt else "sector")
    ok, margins = verify_disturbance(P0, c.P, gains, udot_max=400.0, dt=dt)
    assert ok and len(margins) == len(c.margins)
    # the same P is re-checked, not trusted: a P with a coupling term fails
    bad = c.P.copy()
    bad[0, 3] = bad[3, 0] = 0.5 * np.sqrt(bad[0, 0] * bad[3, 3])
    assert not verify_disturbance(P0, bad, gains, udot_max=400.0, dt=dt)[0]
    # and a P that does not decrease fails (flip the observable block's sign structure)
    assert not verify_disturbance(P0, np.diag([1.0, 1.0, 1.0, 1.0]) * -1, gains, udot_max=400.0,
                                  dt=dt)[0]  # fmt: skip


def test_honest_failures():
    # beta < |gamma|: the hysteresis error can grow; nothing is certified
    q = P0.replace(beta=0.01)
    for dt in (None, DT):
        assert not certify_disturbance(q, G, udot_max=361.0, dt=dt).holds
    # c = l3 / (l3 + l4) > 1: the innovation drives the unobservable combination the wrong way
    g = (G[0], G[1], 1.5 * G[3], -0.5 * G[3])
    c = certify_disturbance(P0, g, udot_max=361.0, dt=DT)
    assert not c.holds and c.status.startswith("not certified")


def test_bad_input():
    with pytest.raises(GainError):
        certify_disturbance(P0, (1.0, 2.0, 3.0), udot_max=1.0)
    with pytest.raises(InputError):
        certify_disturbance(P0, G, udot_max=-1.0)
    with pytest.raises(InputError):
        verify_disturbance(P0, np.eye(3), G, udot_max=1.0)


@pytest.mark.parametrize("gains", [G, G_SPLIT])
def test_brute_force_error_map(gains):
    """Random jump slopes in the certified interval: V never increases, the lumped error dies."""
    c = certify_disturbance(P0, gains, udot_max=2000.0, dt=DT)
    assert c.holds
    pr = _problem(P0, gains, 2000.0, DT, None)
    rng = np.random.default_rng(7)
    for _ in range(20):
        xi = rng.standard_normal(4) * np.array([1.0, 400.0, 1.0, 1.0])
        V = xi @ c.P @ xi
        for k in range(3000):
            rho = rng.uniform(*pr.ends) if k % 2 else 1.0  # the input moves every other sample
            xi = pr.vertex(rho) @ xi
            Vn = xi @ c.P @ xi
            assert Vn <= V * (1 + 1e-12)
            V = Vn
        assert np.abs(xi[:3]).max() < 1e-6


def test_real_observer_follows_the_certified_coordinates():
    """The PHDO on the exact plant: V of its posterior error never increases."""
    t = np.arange(0, 0.5, DT)
    u = 70 + 40 * np.sin(2 * np.pi * 2 * t)
    udot_max = 40 * 2 * np.pi * 2 * 1.01
    X = simulate_zoh(P0, u, DT, x0=np.array([2.0, 0.0, 1.0]))
    c = certify_disturbance(P0, G_SPLIT, udot_max=udot_max, dt=DT)
    assert c.holds
    obs = DisturbanceHysteresisObserver(P0, G_SPLIT, DT, x0=[0.0, 0.0, 0.0, 0.5])
    est = obs.batch_filter(X[1:, 0], u)
    e = np.column_stack([X[1:] - est[:, :3], -est[:, 3]])  # (e1, e2, e3, ed), true d = 0
    ew = e[:, 2] + e[:, 3]
    xi = np.column_stack([e[:, 0], e[:, 1], ew, e[:, 2] - c.split * ew])
    V = np.einsum("ki,ij,kj->k", xi, c.P, xi)
    # round-off floor: the plant states are ~100 um, their errors carry ~1e-13 um of noise
    assert np.all(np.diff(V) <= 1e-9 * V[:-1] + 1e-16 * V[0])
    assert np.abs(xi[-1, :3]).max() < 1e-3 * np.abs(xi[0, :3]).max()


def test_synthesis_certified_and_runs():
    from bwdesign.certify import synthesize_disturbance

    K, cert, why = synthesize_disturbance(P0, udot_max=361.0, dt=DT, decay=100.0)
    assert why == "certified" and cert.holds and K[2] == 0.0
    ok, _ = verify_disturbance(P0, cert.P, udot_max=361.0, dt=DT, discrete=K)
    assert ok
    # the synthesised observer tracks the lumped hysteresis of a mismatched plant
    true = P0.replace(a1=P0.a1 * 1.02, a3=P0.a3 * 0.98, gamma=P0.gamma * 1.1)
    t = np.arange(0, 1.0, DT)
    u = 70 + 40 * np.sin(2 * np.pi * t)
    X = simulate_zoh(true, u, DT, x0=np.zeros(3))
    est = DisturbanceHysteresisObserver(P0, discrete=K, dt=DT).batch_filter(X[1:, 0], u)
    tail = slice(-1000, None)
    assert np.abs(est[tail, 0] - X[1:][tail, 0]).max() < 1e-3 * np.abs(X[1:, 0]).max()
    # beta < |gamma|: refused with the reason
    K2, _, why2 = synthesize_disturbance(P0.replace(beta=0.01), udot_max=361.0, dt=DT)
    assert K2 is None and "beta < |gamma|" in why2
