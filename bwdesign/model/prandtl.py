"""The Prandtl–Ishlinskii (PI) hysteresis operator and its analytic inverse.

The most common hysteresis compensator in the piezo literature: a weighted sum of
play (backlash) operators with thresholds ``0 = r_0 < r_1 < ... < r_{n-1}``::

    z_i[k] = max(v[k] - r_i, min(v[k] + r_i, z_i[k-1]))     (play operator F_{r_i})
    y[k]   = sum_i w_i z_i[k] + c

With ``w_0 > 0`` and every partial sum ``w_0 + ... + w_i > 0`` the operator is
invertible and its inverse is again a PI operator (Krejčí and Kuhnen, "Inverse control
of systems with hysteresis and creep", IEE Proc. Control Theory Appl. 148, 2001), with
thresholds and weights::

    r'_i = sum_{j<=i} w_j (r_i - r_j)
    w'_0 = 1 / w_0,   w'_i = -w_i / ((w_0 + ... + w_i)(w_0 + ... + w_{i-1}))

applied to ``y - c``. The inverse's weights after the first are negative: it is a
PI operator in the general sense this class holds (any real weights); only an
operator that satisfies the partial-sum condition has an inverse
(:meth:`PrandtlIshlinskii.inverse`).

Initial state: every play operator starts at the first input, ``z_i[-1] = v[0]``
(the operator's state after resting at ``v[0]`` from a demagnetised start), unless
``z0`` is given. The inverse of an operator started this way, started the same way
on ``y[0]``, composes with it to the identity (``tests/test_baselines.py``).

The weights are fitted from a record by :func:`bwdesign.identify.prandtl.fit_prandtl_ishlinskii`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..validate import SIGNAL, real

__all__ = ["PrandtlIshlinskii"]


def _floats(values: Any, name: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a sequence of numbers, got {values!r}") from None
    if not out or not all(math.isfinite(v) for v in out):
        raise ParameterError(f"{name} must be a non-empty sequence of finite numbers")
    return out


@dataclass(frozen=True)
class PrandtlIshlinskii:
    """A Prandtl–Ishlinskii operator: play operators with thresholds and weights.

    Parameters
    ----------
    thresholds : sequence of float
        ``r_i`` (input unit), starting at 0, strictly increasing.
    weights : sequence of float
        ``w_i`` (output unit per input unit), one per threshold.
    offset : float
        ``c`` (output unit), added to the weighted sum.

    Raises
    ------
    ParameterError
        Lengths differ, a threshold is negative, the first is not 0, or they are not
        strictly increasing.
    """

    thresholds: tuple[float, ...]
    weights: tuple[float, ...]
    offset: float = 0.0

    def __post_init__(self) -> None:
        r = _floats(self.thresholds, "thresholds")
        w = _floats(self.weights, "weights")
        if len(r) != len(w):
            raise ParameterError(f"thresholds and weights differ in length ({len(r)} and {len(w)})")
        if r[0] != 0.0 or any(b <= a for a, b in zip(r, r[1:], strict=False)):
            raise ParameterError(f"thresholds must start at 0 and increase strictly, got {list(r)}")
        object.__setattr__(self, "thresholds", r)
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "offset", real(self.offset, "offset", within=SIGNAL))

    @property
    def n(self) -> int:
        """Number of play operators."""
        return len(self.thresholds)

    def invertible(self) -> bool:
        """``w_0 > 0`` and every partial sum of the weights positive."""
        return bool(np.all(np.cumsum(self.weights) > 0.0))

    def plays(self, v: Any, z0: Any = None) -> np.ndarray:
        """The play operators' outputs along the input ``v``, shape ``(len(v), n)``.

        ``z0``: their state before ``v[0]`` (default ``v[0]`` for every operator).
        """
        v = np.asarray(v, dtype=float).ravel()
        r = np.asarray(self.thresholds)
        z = np.full(r.size, v[0] if v.size else 0.0) if z0 is None else np.array(z0, dtype=float)
        out = np.empty((v.size, r.size))
        for k, vk in enumerate(v.tolist()):
            z = np.maximum(vk - r, np.minimum(vk + r, z))
            out[k] = z
        return out

    def __call__(self, v: Any, z0: Any = None) -> np.ndarray:
        """The operator's output along ``v`` (output unit).

        Summed in a fixed order, ``((w_0 z_0 + w_1 z_1) + ...) + c``, the order the
        exported C performs (:mod:`bwdesign.codegen.baselines`), so float64 C agrees
        bit for bit.
        """
        z = self.plays(v, z0)
        w = self.weights
        out = z[:, 0] * w[0]
        for i in range(1, self.n):
            out = out + z[:, i] * w[i]
        return out + self.offset

    def inverse(self) -> PrandtlIshlinskii:
        """The analytic inverse (module docstring): maps the output back to the input.

        Raises
        ------
        ParameterError
            The operator is not invertible (a partial sum of its weights <= 0).
        """
        w = np.asarray(self.weights)
        r = np.asarray(self.thresholds)
        s = np.cumsum(w)
        if not np.all(s > 0.0):
            i = int(np.flatnonzero(s <= 0.0)[0])
            raise ParameterError(
                f"the Prandtl-Ishlinskii operator is not invertible: w_0 + ... + w_{i} = "
                f"{s[i]:.6g} <= 0 (the inverse needs w_0 > 0 and every partial sum positive)"
            )
        r_inv = np.array([float(np.sum(w[: i + 1] * (r[i] - r[: i + 1]))) for i in range(r.size)])
        w_inv = np.empty_like(w)
        w_inv[0] = 1.0 / w[0]
        w_inv[1:] = -w[1:] / (s[1:] * s[:-1])
        # the inverse acts on y - c: its offset is -c / w'... folded in by shifting the input
        return _Shifted(tuple(r_inv), tuple(w_inv), 0.0, shift=self.offset)

    def to_dict(self) -> dict[str, Any]:
        return {
            "thresholds": list(self.thresholds),
            "weights": list(self.weights),
            "offset": self.offset,
        }


@dataclass(frozen=True)
class _Shifted(PrandtlIshlinskii):
    """A PI operator applied to ``v - shift`` (the inverse of an operator with an offset)."""

    shift: float = 0.0

    def plays(self, v: Any, z0: Any = None) -> np.ndarray:
        return super().plays(np.asarray(v, dtype=float) - self.shift, z0)

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        d["input_shift"] = self.shift
        return d
