"""The loop's exact response to its reference (bwdesign.certify.response) against a
direct run of the same recursion over many periods, at the loop's own samples."""

import importlib

import numpy as np
import pytest

from bwdesign.model.references import Sine, Step, Triangle

response = importlib.import_module("bwdesign.certify.response")

DT = 5e-5


def _system(seed=3, n=4):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(2, n, n))
    A = 0.97 * A / np.max(np.abs(np.linalg.eigvals(A)), axis=1)[:, None, None]
    B = rng.normal(size=(2, n, 5))
    M = np.zeros((5, 9))
    M[[0, 1, 2, 3], [0, 1, 3, 4]] = 1.0
    M[4, :3] = (2.0, 0.3, 1e-3)
    Lz = rng.normal(size=(2, 3, n))
    Lr = np.zeros((3, 5))
    Lr[2] = rng.normal(size=5)
    return A, B, M, (Lz, Lr, np.array([False, False, True]))


def _direct(A, B, M, rows, ref, n_samples, settling=False):
    Lz, Lr, incr = rows
    t = np.arange(n_samples + 2) * DT
    g = np.stack([np.asarray(w, float) * np.ones_like(t) for w in ref.evaluate(t)], axis=1)
    sig = np.concatenate([g[:-2], g[1:-1], g[2:]], axis=1)
    R = sig @ M.T  # (k, 5)
    out = []
    for p in range(A.shape[0]):
        z = np.zeros(A.shape[1])
        if settling:  # from rest at the reference's first value, every sample counts
            z = np.linalg.solve(np.eye(A.shape[1]) - A[p], B[p] @ R[0])
        Z = np.empty((n_samples, A.shape[1]))
        for k in range(n_samples):
            Z[k] = z
            z = A[p] @ z + B[p] @ R[k]
        Y = Z @ Lz[p].T + R @ Lr.T
        Y[1:, incr] = np.diff(Y[:, incr], axis=0)
        Y[0, incr] = 0.0
        out.append(np.abs(Y[0 if settling else n_samples // 2 :]).max(axis=0))
    return np.array(out)


@pytest.mark.parametrize(
    "ref",
    [
        Sine(amplitude=7.0, offset=8.0, frequency=10.0, phase=0.3),
        Sine(amplitude=3.0, offset=1.0, frequency=7.0),  # 20000/7 samples: 7 periods repeat
        Triangle(amplitude=7.0, offset=8.0, frequency=10.0, corner_time=0.002),  # on samples
        Step(amplitude=15.0, t_step=0.05, rise_time=0.02),
    ],
    ids=["sine", "sine-7Hz", "triangle", "step"],
)
def test_the_exact_response_bounds_a_direct_run_and_is_tight(ref):
    A, B, M, rows = _system()
    bound = response.response_sups(A, B, M, ref, DT, rows)
    assert bound is not None
    if ref.period:  # after the transient of a run from 0
        direct = _direct(A, B, M, rows, ref, 2 * 20000)
    else:
        direct = _direct(A, B, M, rows, ref, int(0.4 / DT), settling=True)
    assert np.all(bound >= direct * (1 - 1e-9)), (bound, direct)
    assert np.all(bound <= direct * 1.02 + 1e-9), bound / direct


def test_a_period_that_is_not_a_small_rational_multiple_of_dt_is_left_to_the_fallback():
    A, B, M, rows = _system()
    ref = Sine(amplitude=1.0, offset=0.0, frequency=1 / (np.pi * 1e-3))
    assert response.response_sups(A, B, M, ref, DT, rows) is None
