"""Fitting a Prandtl–Ishlinskii operator to a record, and the quasi-static record of a model.

:func:`fit_prandtl_ishlinskii` fits the weights of the operator of
:mod:`bwdesign.model.prandtl` to a record ``(t, u, y)`` by constrained linear least
squares (:func:`scipy.optimize.lsq_linear`): the play operators' outputs along ``u``
are the columns, the weights are bounded below by 0 (a PI operator with non-negative
weights is monotone, and with ``w_0 > 0`` invertible), the offset is free. The
thresholds are uniform, ``r_i = i R / n`` with ``R`` half the input's range.

The record goes through the identification's checks
(:meth:`bwdesign.identify.data.IdentificationData.from_arrays`: finite, increasing
uniform time, enough samples, a moving input and output); beyond them the fit refuses
a record whose output does not rise with its input (a PI operator with non-negative
weights cannot describe it) and a fit whose first weight is 0 (no inverse).

The target is the record's *quasi-static* output: with ``dynamics=(a1, a2)`` (the
identified linear part) the fit uses ``y + (a2 y' + y'') / a1`` (central differences),
the output the hysteresis alone would give; without, ``y`` itself (a record slow
enough that the dynamics do not show). :func:`quasi_static_record` gives that output
of a Bouc–Wen model exactly, ``(a3/a1) u - x3``, for an input path.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams
from ..model.plant import hysteresis_increment
from ..model.prandtl import PrandtlIshlinskii
from ..validate import Range, integer
from .data import IdentificationData

__all__ = [
    "PrandtlFit",
    "fit_prandtl_ishlinskii",
    "quasi_static_record",
    "model_record",
    "MONOTONE_SHARE",
]

#: Share of the moving samples on which the output must move with the input.
MONOTONE_SHARE = 0.5


@dataclass(frozen=True)
class PrandtlFit:
    """A fitted Prandtl–Ishlinskii operator and how well it fits.

    Attributes
    ----------
    operator : PrandtlIshlinskii
    rmse : float
        RMS of the fit's residual (output unit).
    range : float
        Peak-to-peak of the fitted output (output unit).
    samples : int
    """

    operator: PrandtlIshlinskii
    rmse: float
    range: float
    samples: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "operator": self.operator.to_dict(),
            "rmse": self.rmse,
            "range": self.range,
            "samples": self.samples,
        }


def quasi_static_record(params: BoucWenParams, u: Any) -> np.ndarray:
    """The quasi-static output ``(a3/a1) u - x3`` of ``params`` along the input path ``u``.

    ``x3`` starts at 0 and follows the exact hysteresis increment between samples.
    """
    u = np.asarray(u, dtype=float).ravel()
    h = np.empty_like(u)
    hk, uk = 0.0, float(u[0])
    for k, v in enumerate(u.tolist()):
        hk = hysteresis_increment(params, hk, uk, v)
        uk = v
        h[k] = hk
    return params.a3 / params.a1 * u - h


def _target(data: IdentificationData, dynamics: Any) -> np.ndarray:
    if dynamics is None:
        return np.asarray(data.y, dtype=float)
    try:
        a1, a2 = (float(v) for v in dynamics)
    except (TypeError, ValueError):
        raise InputError(f"dynamics must be (a1, a2), got {dynamics!r}") from None
    if not a1 > 0:
        raise InputError(f"dynamics: a1 must be > 0, got {a1}")
    y = np.asarray(data.y, dtype=float)
    yd = np.gradient(y, data.dt)
    ydd = np.gradient(yd, data.dt)
    return y + (a2 * yd + ydd) / a1


def _check_monotone(u: np.ndarray, y: np.ndarray, where: str) -> None:
    du, dy = np.diff(u), np.diff(y)
    moving = np.abs(du) > 1e-9 * max(1.0, float(np.max(np.abs(u))))
    if not moving.any():
        raise InputError(f"{where}the input never moves: nothing to fit")
    agree = float(np.mean(np.sign(du[moving]) == np.sign(dy[moving])))
    if agree < MONOTONE_SHARE:
        raise InputError(
            f"{where}the output does not rise with the input (it moves with it on "
            f"{100 * agree:.3g} % of the moving samples, fewer than {100 * MONOTONE_SHARE:g} %): "
            "a Prandtl-Ishlinskii operator with non-negative weights is monotone and cannot "
            "fit this record (a sign error in u or y, or a record dominated by dynamics?)"
        )


def fit_prandtl_ishlinskii(data: Any, *, n_operators: int = 10, dynamics: Any = None) -> PrandtlFit:
    """Fit a PI operator to a record (module docstring).

    Parameters
    ----------
    data : IdentificationData or (t, u, y)
        The record (s, input unit, output unit); arrays are checked as
        :meth:`IdentificationData.from_arrays` checks them.
    n_operators : int
        Number of play operators (2 .. 200).
    dynamics : (a1, a2), optional
        The linear part's stiffness and damping per unit mass: fit the quasi-static
        output ``y + (a2 y' + y'')/a1`` instead of ``y``.

    Returns
    -------
    PrandtlFit

    Raises
    ------
    InputError
        A record the checks refuse, an output that does not rise with the input, or a
        fit with ``w_0 = 0`` (not invertible).
    """
    if not isinstance(data, IdentificationData):
        try:
            t, u, y = data
        except (TypeError, ValueError):
            raise InputError(
                f"data must be an IdentificationData or (t, u, y), got {type(data).__name__}"
            ) from None
        data = IdentificationData.from_arrays(t, u, y, source="Prandtl-Ishlinskii record")
    n = integer(n_operators, "n_operators", within=Range(2, 200))
    where = f"{data.source}: " if data.source else ""
    u = np.asarray(data.u, dtype=float)
    y = _target(data, dynamics)
    _check_monotone(u, y, where)
    half = 0.5 * float(np.ptp(u))
    thresholds = tuple(i * half / n for i in range(n))
    shape = PrandtlIshlinskii(thresholds, (1.0,) * n)
    A = np.column_stack([shape.plays(u), np.ones(u.size)])
    from scipy.optimize import lsq_linear  # the fit alone needs it

    lo = np.r_[np.zeros(n), -np.inf]
    sol = lsq_linear(A, y, bounds=(lo, np.full(n + 1, np.inf)), method="bvls")
    w, c = sol.x[:n], float(sol.x[n])
    if not w[0] > 0.0:
        raise InputError(
            f"{where}the fit gives w_0 = {w[0]:.3g}: the operator would not be invertible "
            "(the record shows no immediate response to a reversal of the input)"
        )
    op = PrandtlIshlinskii(thresholds, tuple(float(v) for v in w), c)
    res = A @ sol.x - y
    return PrandtlFit(
        operator=op,
        rmse=float(np.sqrt(np.mean(res * res))),
        range=float(np.ptp(y)),
        samples=int(u.size),
    )


def model_record(params: BoucWenParams, y_range: Any, *, samples: int = 4000) -> tuple:
    """A quasi-static record ``(t, u, y)`` of ``params`` covering the outputs ``y_range``.

    The input is a sine about the middle of the input range those outputs need
    (``u = a1 (y +- h_max)/a3``), its amplitude decaying from the whole range to a fifth
    over four cycles so that the record holds minor loops; ``y`` is
    :func:`quasi_static_record` (exact). The time axis is nominal (1 ms per sample): a
    quasi-static record has no rate.
    """
    try:
        y_lo, y_hi = sorted(float(v) for v in y_range)
    except (TypeError, ValueError):
        raise InputError(f"y_range must be (y_min, y_max), got {y_range!r}") from None
    bc = params.bounded_class()
    h = bc.h_max if bc.bounded else abs(params.alpha)
    u_lo = params.a1 * (y_lo - h) / params.a3
    u_hi = params.a1 * (y_hi + h) / params.a3
    s = np.arange(samples) / samples
    u = 0.5 * (u_lo + u_hi) + 0.5 * (u_hi - u_lo) * (1 - 0.8 * s) * np.sin(8 * np.pi * s)
    return s * samples * 1e-3, u, quasi_static_record(params, u)
