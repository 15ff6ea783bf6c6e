"""Observer gains: validation, the error matrix and pole matching to discrete gains."""

from __future__ import annotations

import math
from numbers import Real
from typing import Any

import numpy as np

from ..errors import GainError
from ..model.params import BoucWenParams
from ..model.plant import _check_dt, discretize
from ..validate import GAIN

__all__ = ["check_gains", "error_matrix", "discrete_gains"]


C = np.array([1.0, 0.0, 0.0])


def _as_gains(gains: Any, what: str = "gains") -> np.ndarray:
    try:
        g = np.asarray(gains)
    except (TypeError, ValueError):
        raise GainError(f"{what} must be three numbers (l1, l2, l3), got {gains!r}") from None
    bools = isinstance(gains, list | tuple) and any(isinstance(v, bool | np.bool_) for v in gains)
    if g.dtype.kind not in "fiu" or bools:  # strings, booleans, None
        raise GainError(f"{what} must be three numbers (l1, l2, l3), got {gains!r}")
    g = g.astype(float)
    if g.shape != (3,):
        raise GainError(f"{what} must be three numbers (l1, l2, l3), got shape {g.shape}")
    if not np.all(np.isfinite(g)):
        raise GainError(f"{what} must be finite, got {g.tolist()}")
    for v in np.asarray(gains, dtype=object).ravel():
        if not isinstance(v, Real) or isinstance(v, bool):
            raise GainError(f"{what} must be numbers, got {type(v).__name__} {v!r}")
    if not all(x in GAIN for x in g.tolist()):
        raise GainError(f"{what} {g.tolist()} are outside the supported range {GAIN.text()}")
    return g


def check_gains(params: BoucWenParams, gains: Any) -> np.ndarray:
    """Validate continuous observer gains against the Hurwitz conditions (4).

    ``l1 + a2 > 0``, ``(l1 + a2)(l1 a2 + a1 + l2) + l3 a1 > 0`` and ``l3 a1 < 0``
    make ``A0 - l C`` Hurwitz (Routh-Hurwitz on its characteristic polynomial).

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    GainError
        Wrong length, non-finite, or a violated condition (named in the message).
    """
    l1, l2, l3 = g = _as_gains(gains)
    a1, a2 = params.a1, params.a2
    c2 = (l1 + a2) * (l1 * a2 + a1 + l2) + l3 * a1
    failed = []
    if not l1 + a2 > 0:
        failed.append(f"l1 + a2 > 0 (it is {l1 + a2:.6g})")
    if not c2 > 0:
        failed.append(
            f"(l1 + a2)(l1 a2 + a1 + l2) + l3 a1 > 0 (it is {c2:.6g}; raise l1 or l2, "
            "or reduce |l3|)"
        )
    if not l3 * a1 < 0:
        failed.append("l3 a1 < 0 (l3 must be negative)")
    if failed:
        raise GainError(
            f"observer gains l = ({l1:g}, {l2:g}, {l3:g}) on {params.name or 'the plant'}: "
            f"A = A0 - l C is not Hurwitz; they violate {'; '.join(failed)}"
        )
    return g


def error_matrix(params: BoucWenParams, gains: Any) -> np.ndarray:
    """Continuous error matrix ``A = A0 - l C`` of paper eq. (5).

    ``A = [[-l1, 1, 0], [-(a1 + l2), -a2, -a1], [-l3, 0, 0]]``.
    """
    l1, l2, l3 = _as_gains(gains)
    return np.array([[-l1, 1.0, 0.0], [-(params.a1 + l2), -params.a2, -params.a1], [-l3, 0.0, 0.0]])


def discrete_gains(params: BoucWenParams, gains: Any, dt: float) -> np.ndarray:
    """Discrete correction ``K`` whose error poles are ``exp(lambda_i dt)``.

    ``lambda_i`` are the eigenvalues of ``A0 - l C``. Ackermann's formula for
    the pair ``(F, C F)`` places the eigenvalues of ``(I - K C) F``; it is
    evaluated with ``x2`` scaled by ``sqrt(a1)`` so the 3x3 problem is well
    conditioned for a1 from 1e3 to 1e9, and it handles repeated poles.

    Parameters
    ----------
    params : BoucWenParams
    gains : array_like, shape (3,)
        Continuous gains (1/s, 1/s^2, 1/s).
    dt : float
        Sample time (s).

    Returns
    -------
    ndarray, shape (3,)
    """
    lam = np.linalg.eigvals(error_matrix(params, gains))
    return place_discrete(params, np.exp(lam * _check_dt(dt)), dt)


def place_discrete(params: BoucWenParams, poles: np.ndarray, dt: float) -> np.ndarray:
    """``K`` with eig((I - K C) F) = ``poles`` (a self-conjugate set of three)."""
    F = discretize(params, dt).F
    w0 = math.sqrt(params.a1)
    s = np.array([1.0, 1.0 / w0, 1.0])  # z = S x
    Fz = s[:, None] * F / s[None, :]
    Hz = (C @ F) / s
    O = np.vstack([Hz, Hz @ Fz, Hz @ Fz @ Fz])
    coeffs = np.real(np.poly(poles))
    pF = coeffs[0] * Fz @ Fz @ Fz + coeffs[1] * Fz @ Fz + coeffs[2] * Fz + coeffs[3] * np.eye(3)
    try:
        Kz = pF @ np.linalg.solve(O, np.array([0.0, 0.0, 1.0]))
    except np.linalg.LinAlgError:
        raise GainError(
            f"the sampled model is not observable at dt = {dt:g} s; choose another dt"
        ) from None
    return Kz / s
