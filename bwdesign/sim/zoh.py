"""The true plants' exact ZOH matrices, for one run and for a batch, computed one way.

:func:`true_matrices` stacks the augmented exponential of every plant's linear part and
takes it by scaling and squaring with a degree-18 Taylor series (one vectorised pass
instead of N calls of :func:`scipy.linalg.expm`). :func:`bwdesign.sim.simulate` takes its
true plant's matrices from here too (a batch of one), so a run and the same scenario of
:func:`bwdesign.sim.simulate_batch` step the same numbers and agree to the last bit; the
model's matrices (the observer's) are :func:`bwdesign.model.plant.discretize`'s.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.params import BoucWenParams

__all__ = ["true_matrices"]


def _zoh_batch(a1: np.ndarray, a2: np.ndarray, a3: np.ndarray, dt: float) -> np.ndarray:
    """:func:`bwdesign.model.plant.discretize`'s augmented exponential, stacked (N, 4, 4)."""
    w0 = np.sqrt(a1)
    n = a1.size
    Mz = np.zeros((n, 4, 4))
    Mz[:, 0, 1] = w0
    Mz[:, 1, 0] = -w0
    Mz[:, 1, 1] = -a2
    Mz[:, 1, 2] = -w0
    Mz[:, 1, 3] = w0
    D = np.stack([np.ones(n), w0, np.ones(n), a1 / a3], axis=1)
    return D[:, :, None] * _expm_stack(Mz * dt) / D[:, None, :]


def _expm_stack(A: np.ndarray) -> np.ndarray:
    """``expm`` of a stack of small matrices (N, m, m): scaling and squaring with Taylor.

    One vectorised pass instead of N calls of :func:`scipy.linalg.expm` (which costs
    more than the simulation for short runs). After scaling to ``||A/2^s||_1 <= 1/2``
    the degree-18 Taylor remainder is below ``0.5^19 / 19! ~ 2e-23``, far below
    double rounding; the result agrees with scipy to rounding (checked in the tests).
    """
    norm = float(np.max(np.abs(A).sum(axis=-2))) if A.size else 0.0
    s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    X = A / 2.0**s
    eye = np.broadcast_to(np.eye(A.shape[-1]), A.shape)
    E = eye.copy()
    term = eye.copy()
    for k in range(1, 19):
        term = term @ X / k
        E = E + term
    for _ in range(s):
        E = E @ E
    return E


def true_matrices(true_params: list[BoucWenParams], dt: float) -> dict[str, np.ndarray]:
    """The ZOH entries ``p11..p23``, ``g1``, ``g2``, ``w0`` and the hysteresis parameters
    of each plant, as arrays (one entry per plant)."""
    col = {k: np.array([getattr(tp, k) for tp in true_params]) for k in ("a1", "a2", "a3")}
    E = _zoh_batch(col["a1"], col["a2"], col["a3"], dt)
    out = {f"p{i + 1}{j + 1}": E[:, i, j].copy() for i in range(2) for j in range(3)}
    out.update(g1=E[:, 0, 3].copy(), g2=E[:, 1, 3].copy(), w0=np.sqrt(col["a1"]))
    for k in ("alpha", "beta", "gamma"):
        out[k] = np.array([getattr(tp, k) for tp in true_params])
    return out
