"""The true plants' exact ZOH matrices, for one run and for a batch, computed one way.

:func:`true_matrices` takes every plant's matrices from
:func:`bwdesign.model.plant.discretize` (scipy's ``expm`` of the balanced augmented
matrix, about 20 us a plant), as the observer's model matrices are. One run
(:func:`bwdesign.sim.simulate`) and the same scenario of a batch
(:func:`bwdesign.sim.simulate_batch`) so step the same numbers and agree to the last bit,
and a run on the nominal plant estimates it with no error at all.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.params import BoucWenParams
from ..model.plant import discretize

__all__ = ["true_matrices"]

_ENTRIES = ("p11", "p12", "p13", "p21", "p22", "p23")


def true_matrices(true_params: list[BoucWenParams], dt: float) -> dict[str, np.ndarray]:
    """The ZOH entries ``p11..p23``, ``g1``, ``g2``, ``w0`` and the hysteresis parameters
    of each plant, as arrays (one entry per plant)."""
    n = len(true_params)
    out = {k: np.empty(n) for k in (*_ENTRIES, "g1", "g2", "w0")}
    for i, tp in enumerate(true_params):
        z = discretize(tp, dt)
        for r in range(2):
            for c in range(3):
                out[f"p{r + 1}{c + 1}"][i] = z.F[r, c]
        out["g1"][i], out["g2"][i] = z.g[0], z.g[1]
        out["w0"][i] = math.sqrt(tp.a1)
    for k in ("alpha", "beta", "gamma"):
        out[k] = np.array([getattr(tp, k) for tp in true_params], dtype=float)
    return out
