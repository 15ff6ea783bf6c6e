"""Linear analysis of the observer error dynamics with python-control.

The estimation error of the hysteresis observer obeys
``eps' = A eps + e3 phi~`` with ``A = A0 - l C`` and ``phi~ = -k eps3``,
``k`` in the sector interval of :func:`bwdesign.certify.sector_interval`.
This module gives

- the error dynamics as :class:`control.StateSpace` objects at the two ends of
  the sector (input ``phi~``, output ``eps3``), with poles, damping ratios and
  natural frequencies (:func:`error_dynamics`);
- the magnitude of ``G(s) = e3' (sI - A)^-1 e3``, the transfer function from
  the hysteresis error to ``eps3``, and its H-infinity peak from
  :func:`control.linfnorm` (needs slycot). By the KYP lemma the ``lipschitz``
  certificate holds exactly when ``(|beta| + |gamma|) udot_max ||G||_inf < 1``,
  so :func:`lipschitz_envelope` is an independent cross-check of the LMI
  envelope (:func:`hysteresis_bode`).

Norms and poles are computed on the scaled system (``x2`` scaled by
``sqrt(a1)``, time by ``sqrt(a1)``, then balanced), where the matrices are of
order one for ``a1`` from 1e3 to 1e9, and mapped back:
``||G||_inf = ||G_hat||_inf / w`` and ``omega = w omega_hat``.

python-control is imported inside the functions, so ``import bwdesign`` stays
light.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams
from ..observers.gains import check_gains, error_matrix
from ..validate import DECAY, UDOT_BOUND, real
from .checks import scale_continuous, sector_interval

__all__ = [
    "ErrorDynamics",
    "HysteresisBode",
    "error_system",
    "error_dynamics",
    "hinf_norm",
    "hysteresis_bode",
    "lipschitz_envelope",
]


def _damping(poles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    wn = np.abs(poles)
    zeta = np.where(wn > 0, -poles.real / np.where(wn > 0, wn, 1.0), -1.0)
    return wn, zeta


def error_system(
    params: BoucWenParams, gains: Sequence[float], *, k: float = 0.0, decay: float = 0.0
) -> Any:
    """The error dynamics ``eps' = (A - k e3 e3' + decay I) eps + e3 w``, output ``eps3``.

    Parameters
    ----------
    params : BoucWenParams
    gains : sequence of 3 floats
        ``(l1, l2, l3)`` (1/s, 1/s^2, 1/s); must satisfy the Hurwitz conditions.
    k : float
        Feedback of the hysteresis error on ``eps3`` (1/s).
    decay : float
        Shift ``mu`` (1/s): the system whose stability means decay faster than ``mu``.

    Returns
    -------
    control.StateSpace
        In original coordinates (µm, µm/s, µm; time in s).
    """
    import control

    gains = tuple(check_gains(params, gains).tolist())
    A = error_matrix(params, gains)
    A[2, 2] -= float(k)
    A += float(decay) * np.eye(3)
    return control.ss(A, [[0.0], [0.0], [1.0]], [[0.0, 0.0, 1.0]], [[0.0]])


def _scaled_system(params: BoucWenParams, gains: Sequence[float], *, k: float, decay: float):
    import control

    sc = scale_continuous(params, error_matrix(params, gains))
    Ah = sc.Ahat.copy()
    Ah[2, 2] -= k / sc.w
    Ah += (decay / sc.w) * np.eye(3)
    return control.ss(Ah, [[0.0], [0.0], [1.0]], [[0.0, 0.0, 1.0]], [[0.0]]), sc.w


@dataclass(frozen=True)
class ErrorDynamics:
    """The observer error dynamics at the two ends of the sector interval.

    Attributes
    ----------
    udot_max : float
        Input-rate bound (V/s) defining the interval.
    k_interval : (float, float)
        ``(k_lo, k_hi)`` (1/s).
    systems : tuple of control.StateSpace
        ``A - k e3 e3'`` with input ``phi~`` and output ``eps3``, at ``k_lo`` and ``k_hi``.
    poles : tuple of ndarray
        Eigenvalues (rad/s) at each end.
    natural_frequency : tuple of ndarray
        ``|pole|`` (rad/s).
    damping : tuple of ndarray
        ``-Re(pole)/|pole|``.
    """

    udot_max: float
    k_interval: tuple[float, float]
    systems: tuple[Any, Any]
    poles: tuple[np.ndarray, np.ndarray]
    natural_frequency: tuple[np.ndarray, np.ndarray]
    damping: tuple[np.ndarray, np.ndarray]

    @property
    def stable(self) -> bool:
        """True when both end systems are Hurwitz (necessary for the sector tier)."""
        return all(float(np.max(p.real)) < 0 for p in self.poles)

    def to_dict(self) -> dict[str, Any]:
        ends = []
        for k, p, wn, z in zip(
            self.k_interval, self.poles, self.natural_frequency, self.damping, strict=True
        ):
            ends.append(
                {
                    "k": k,
                    "poles": [[float(x.real), float(x.imag)] for x in p],
                    "natural_frequency": wn.tolist(),
                    "damping": z.tolist(),
                }
            )
        return {"udot_max": self.udot_max, "ends": ends, "stable": self.stable}


def error_dynamics(
    params: BoucWenParams, gains: Sequence[float], *, udot_max: float
) -> ErrorDynamics:
    """State space, poles and damping at both ends of the sector interval.

    Parameters
    ----------
    params : BoucWenParams
    gains : sequence of 3 floats
        ``(l1, l2, l3)``.
    udot_max : float
        Input-rate bound (V/s), >= 0.

    Examples
    --------
    >>> from bwdesign import preset
    >>> ed = error_dynamics(preset("paper_experiment"), (8, 64, -512), udot_max=360.9)
    >>> ed.stable
    True
    """
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_BOUND)
    gains = tuple(check_gains(params, gains).tolist())
    k_int = sector_interval(params, udot_max)
    sc = scale_continuous(params, error_matrix(params, gains))
    systems, poles, wns, zetas = [], [], [], []
    for k in k_int:
        systems.append(error_system(params, gains, k=k))
        Ah = sc.Ahat.copy()
        Ah[2, 2] -= k / sc.w
        p = np.sort_complex(np.linalg.eigvals(Ah) * sc.w)
        wn, zeta = _damping(p)
        poles.append(p)
        wns.append(wn)
        zetas.append(zeta)
    return ErrorDynamics(
        udot_max=udot_max,
        k_interval=(float(k_int[0]), float(k_int[1])),
        systems=tuple(systems),
        poles=tuple(poles),
        natural_frequency=tuple(wns),
        damping=tuple(zetas),
    )


def hinf_norm(
    params: BoucWenParams, gains: Sequence[float], *, decay: float = 0.0
) -> tuple[float, float]:
    """H-infinity norm of ``e3' (sI - A - decay I)^-1 e3`` with :func:`control.linfnorm`.

    Returns
    -------
    peak : float
        The norm (µm per µm/s, i.e. s); ``inf`` when ``A + decay I`` is not Hurwitz.
    omega_peak : float
        Frequency of the peak (rad/s).
    """
    import control

    decay = real(decay, "decay (1/s)", within=DECAY)
    gains = tuple(check_gains(params, gains).tolist())
    sys_hat, w = _scaled_system(params, gains, k=0.0, decay=decay)
    if float(np.max(np.linalg.eigvals(sys_hat.A).real)) >= 0:
        return math.inf, 0.0
    peak, omega = control.linfnorm(sys_hat)
    return float(peak) / w, float(omega) * w


def lipschitz_envelope(
    params: BoucWenParams, gains: Sequence[float], *, decay: float = 0.0
) -> float:
    """``1 / ((|beta| + |gamma|) ||G||_inf)`` (V/s): the lipschitz tier's exact envelope."""
    peak, _ = hinf_norm(params, gains, decay=decay)
    c = abs(params.beta) + abs(params.gamma)
    if c == 0:
        return math.inf
    return 0.0 if math.isinf(peak) else 1.0 / (c * peak)


@dataclass(frozen=True)
class HysteresisBode:
    """Magnitude of the hysteresis-error-to-``eps3`` transfer function.

    Attributes
    ----------
    omega : ndarray
        Frequencies (rad/s).
    magnitude : ndarray
        ``|G(j omega)|`` (s).
    peak : float
        H-infinity norm from :func:`control.linfnorm` (s).
    omega_peak : float
        Its frequency (rad/s).
    lipschitz_envelope : float
        ``1 / ((|beta| + |gamma|) peak)`` (V/s).
    """

    omega: np.ndarray
    magnitude: np.ndarray
    peak: float
    omega_peak: float
    lipschitz_envelope: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "omega": self.omega.tolist(),
            "magnitude": self.magnitude.tolist(),
            "peak": self.peak,
            "omega_peak": self.omega_peak,
            "lipschitz_envelope": self.lipschitz_envelope,
        }


def hysteresis_bode(
    params: BoucWenParams,
    gains: Sequence[float],
    *,
    omega: Sequence[float] | None = None,
    n: int = 400,
) -> HysteresisBode:
    """Bode magnitude of ``G(s) = e3' (sI - A)^-1 e3`` and its H-infinity peak.

    Parameters
    ----------
    params : BoucWenParams
    gains : sequence of 3 floats
        ``(l1, l2, l3)``.
    omega : sequence of float, optional
        Frequencies (rad/s, > 0). Default: ``n`` log-spaced points from 1/100 of
        the slowest to 100 times the fastest pole, plus the peak frequency.
    n : int
        Number of default grid points.

    Examples
    --------
    >>> from bwdesign import preset
    >>> b = hysteresis_bode(preset("paper_experiment"), (8, 64, -512))
    >>> round(b.lipschitz_envelope)
    155
    """
    import control

    gains = tuple(check_gains(params, gains).tolist())
    sys_hat, w = _scaled_system(params, gains, k=0.0, decay=0.0)
    peak_h, omega_h = control.linfnorm(sys_hat)
    peak, omega_peak = float(peak_h) / w, float(omega_h) * w
    if omega is None:
        p = np.abs(np.linalg.eigvals(sys_hat.A)) * w
        lo = max(float(p[p > 0].min()) if np.any(p > 0) else 1.0, 1e-12) / 100
        hi = float(p.max()) * 100 if p.max() > 0 else 1e3
        grid = np.logspace(math.log10(lo), math.log10(hi), int(n))
        if omega_peak > 0:
            grid = np.unique(np.append(grid, omega_peak))
    else:
        grid = np.asarray(omega, dtype=float).ravel()
        if grid.size == 0 or not np.all(np.isfinite(grid)) or np.any(grid <= 0):
            raise InputError("omega must be a non-empty sequence of finite frequencies > 0 (rad/s)")
    resp = control.frequency_response(sys_hat, grid / w)
    mag = np.asarray(np.squeeze(resp.magnitude), dtype=float).reshape(grid.shape) / w
    c = abs(params.beta) + abs(params.gamma)
    return HysteresisBode(
        omega=grid,
        magnitude=mag,
        peak=peak,
        omega_peak=omega_peak,
        lipschitz_envelope=math.inf if c == 0 else 1.0 / (c * peak),
    )
