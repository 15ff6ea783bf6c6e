"""Unscented Kalman filter baseline: what a user would otherwise reach for.

:class:`UnscentedObserver` wraps :class:`filterpy.kalman.UnscentedKalmanFilter`
with the *exact* sampled plant as its process model (state x1, x2, x3; the
hysteresis follows the jump ``u_{k-1} -> u_k`` in closed form, then the linear
part is propagated with the ZOH matrices: :func:`bwdesign.model.plant.zoh_step`) and
``y = x1`` as its measurement model. It has the interface of the other
observers (``predict(u)``, ``update(z)``, ``batch_filter(zs, us)``, ``x``,
``x_prior``, ``x_post``), plus the covariances ``P``, ``P_prior``, ``P_post``.

Default noise model (:func:`default_noise`), for a plant in length unit L
(µm for the paper presets) and input in V:

- ``R = noise_std**2``: the variance of the displacement sensor (L^2).
- ``Q = s_h**2 g g^T`` with ``s_h = max|dh/du| * udot_max * dt`` and
  ``g = F[:, 2]`` the column of the ZOH matrix through which the hysteresis
  state enters the next sample. ``s_h`` is the largest hysteresis increment
  over one sample inside the envelope ``|u'| <= udot_max``: along a jump,
  ``dh/du = alpha - beta s h - gamma |h|``, whose magnitude is at most
  ``alpha + |beta - gamma| h_max`` with ``h_max = alpha/(beta + gamma)``
  (largest just after a reversal). So the filter is told that x3 may move by
  up to one full envelope increment per sample beyond what its model says,
  and that this uncertainty reaches x1, x2 through the plant (rank-one Q).
- ``P0 = diag(h_max^2, (sqrt(a1) h_max)^2, h_max^2)``: an initial uncertainty
  the size of the hysteresis range in x1 and x3, and the matching velocity
  scale (an x1 offset of ``h_max`` released at the natural frequency
  ``sqrt(a1)``) in x2.
- Sigma points: :class:`filterpy.kalman.MerweScaledSigmaPoints` with
  ``alpha = 1``, ``beta = 2``, ``kappa = 0`` (points at ``sqrt(3)`` standard
  deviations, so they straddle the ``|x3|`` kink of the hysteresis within the
  current uncertainty rather than linearising at the mean, as the common
  ``alpha = 1e-3`` effectively does).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from ..errors import GainError, InputError
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_dt, discretize, hysteresis_slope_range, zoh_step
from ..validate import POSITIVE, UDOT_MAX, real
from .base import (
    as_inputs,
    as_measurements,
    check_params,
    finite_scalar,
    require_finite_state,
    state_vector,
)

__all__ = ["UnscentedObserver", "default_noise", "max_hysteresis_slope"]


def max_hysteresis_slope(params: BoucWenParams) -> float:
    """Upper bound of ``|dh/du|`` over the bounded hysteresis range (length unit/V).

    ``alpha + (beta - gamma) h_max`` with ``h_max = alpha/(beta + gamma)``; for a
    model outside the bounded class (no ``h_max``) it is ``alpha``
    (:func:`bwdesign.model.plant.hysteresis_slope_range`).
    """
    return hysteresis_slope_range(params)[1]


def default_noise(
    params: BoucWenParams, dt: float, *, udot_max: float, noise_std: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The documented default ``(Q, R, P0)`` of :class:`UnscentedObserver`.

    Parameters
    ----------
    params : BoucWenParams
    dt : float
        Sample time (s).
    udot_max : float
        Input-rate envelope (V/s), e.g. ``bwdesign.derive_envelope(...).udot_max``.
    noise_std : float
        Standard deviation of the displacement measurement (length unit).

    Returns
    -------
    Q : ndarray, shape (3, 3)
        ``s_h^2 g g^T`` (see the module docstring).
    R : ndarray, shape (1, 1)
        ``noise_std^2``.
    P0 : ndarray, shape (3, 3)
        ``diag(h_max^2, a1 h_max^2, h_max^2)``.
    """
    dt = check_dt(dt)
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_MAX)
    noise_std = real(noise_std, "noise_std (length unit)", within=POSITIVE)
    s_h = max_hysteresis_slope(params) * udot_max * dt
    g = discretize(params, dt).F[:, 2]
    Q = s_h**2 * np.outer(g, g)
    R = np.array([[noise_std**2]])
    verdict = params.bounded_class()
    h = verdict.h_max if verdict.bounded else params.alpha
    P0 = np.diag([h**2, params.a1 * h**2, h**2])
    return Q, R, P0


def _matrix(M: Any, shape: tuple[int, int], name: str) -> np.ndarray:
    try:
        A = np.array(M, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a {shape} array of numbers, got {M!r}") from None
    if A.shape == () and shape == (1, 1):
        A = A.reshape(1, 1)
    if A.shape != shape or not np.all(np.isfinite(A)):
        raise InputError(f"{name} must be a finite array of shape {shape}, got {A.shape}")
    if not np.allclose(A, A.T, rtol=1e-12, atol=0.0):
        raise InputError(f"{name} must be symmetric")
    if np.linalg.eigvalsh(A).min() < -1e-12 * max(1.0, float(np.abs(A).max())):
        raise InputError(f"{name} must be positive semidefinite")
    return A


def _plant_step(params: BoucWenParams, x: np.ndarray, dt: float, u_prev: float, u: float):
    """filterpy's ``fx(x, dt, **fx_args)``: one exact sample of the plant."""
    return zoh_step(params, x, u_prev, u, dt)


def _position(x: np.ndarray) -> np.ndarray:
    """filterpy's ``hx(x)``: the measured displacement x1."""
    return x[:1]


class UnscentedObserver:
    """UKF on the exact sampled plant, with the observers' filterpy-style interface.

    Parameters
    ----------
    params : BoucWenParams
    dt : float
        Sample time (s).
    udot_max : float, optional
        Input-rate envelope (V/s) used for the default ``Q``; required unless
        ``Q`` is given.
    noise_std : float
        Displacement sensor standard deviation (length unit) used for the
        default ``R``. The default 0.01 is 10 nm for a plant in µm.
    Q : array_like, shape (3, 3), optional
        Process noise covariance (see :func:`default_noise`).
    R : float or array_like, shape (1, 1), optional
        Measurement noise variance (length unit^2).
    P0 : array_like, shape (3, 3), optional
        Initial covariance.
    x0 : array_like, shape (3,), optional
        Initial estimate (default zeros).
    u_prev : float
        Input held before the first sample (V).
    points : filterpy sigma-point object, optional
        Default ``MerweScaledSigmaPoints(3, alpha=1.0, beta=2.0, kappa=0.0)``.
    allow_unbounded : bool
        Accept parameters outside the bounded class.

    Attributes
    ----------
    ukf : filterpy.kalman.UnscentedKalmanFilter
        The wrapped filter (its ``fx`` takes ``u_prev`` and ``u`` keywords).
    u_prev : float
        Input held over the previous sample (V).

    Examples
    --------
    >>> from bwdesign import preset
    >>> obs = UnscentedObserver(preset("paper_experiment"), 2e-4, udot_max=500.0)
    >>> obs.predict(1.0); obs.update(0.0)
    >>> obs.x.shape, obs.P.shape
    ((3,), (3, 3))
    """

    kind = "ukf"

    def __init__(
        self,
        params: BoucWenParams,
        dt: float = 2e-4,
        *,
        udot_max: float | None = None,
        noise_std: float = 0.01,
        Q: Any = None,
        R: Any = None,
        P0: Any = None,
        x0: Any = None,
        u_prev: float = 0.0,
        points: Any = None,
        allow_unbounded: bool = False,
    ) -> None:
        # filterpy pulls in scipy.stats (~0.4 s): imported here, not with bwdesign
        from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

        check_params(params, "UnscentedObserver")
        require_bounded(params, allow_unbounded)
        self.params = params
        self.dt = check_dt(dt)
        if Q is None and udot_max is None:
            raise InputError(
                "UnscentedObserver: give udot_max (V/s, the input-rate envelope) for the "
                "default Q, or Q itself"
            )
        if Q is None or R is None or P0 is None:
            Qd, Rd, Pd = default_noise(
                params,
                self.dt,
                udot_max=1.0 if udot_max is None else udot_max,
                noise_std=noise_std,
            )
        self.udot_max = (
            None if udot_max is None else real(udot_max, "udot_max (V/s)", within=UDOT_MAX)
        )
        self.noise_std = real(noise_std, "noise_std (length unit)", within=POSITIVE)
        if points is None:
            points = MerweScaledSigmaPoints(3, alpha=1.0, beta=2.0, kappa=0.0)
        self.ukf = UnscentedKalmanFilter(
            dim_x=3,
            dim_z=1,
            dt=self.dt,
            hx=_position,
            fx=functools.partial(_plant_step, params),
            points=points,
        )
        self.ukf.Q = Qd if Q is None else _matrix(Q, (3, 3), "Q")
        self.ukf.R = Rd if R is None else _matrix(R, (1, 1), "R")
        self._P0 = Pd if P0 is None else _matrix(P0, (3, 3), "P0")
        self.reset(x0, u_prev=u_prev)

    # -- state -------------------------------------------------------------
    def reset(self, x0: Any = None, *, u_prev: float = 0.0, P0: Any = None) -> None:
        """Restart from ``x0`` (default zeros) and ``P0`` (default: the constructor's)."""
        x = np.zeros(3) if x0 is None else state_vector(x0, "x0")
        P = self._P0 if P0 is None else _matrix(P0, (3, 3), "P0")
        f = self.ukf
        f.x, f.P = x, P.copy()
        f.x_prior, f.P_prior = x.copy(), P.copy()
        f.x_post, f.P_post = x.copy(), P.copy()
        self.u_prev = finite_scalar(u_prev, "u_prev")
        self.y = 0.0
        self.z: float | None = None

    @property
    def x(self) -> np.ndarray:
        """Current estimate, shape (3,)."""
        return self.ukf.x

    @x.setter
    def x(self, value: Any) -> None:
        self.ukf.x = state_vector(value, "x")

    @property
    def P(self) -> np.ndarray:
        """Current covariance, shape (3, 3)."""
        return self.ukf.P

    @P.setter
    def P(self, value: Any) -> None:
        self.ukf.P = np.asarray(value, dtype=float)

    @property
    def x_prior(self) -> np.ndarray:
        """Estimate after the last ``predict``."""
        return self.ukf.x_prior

    @property
    def x_post(self) -> np.ndarray:
        """Estimate after the last ``update``."""
        return self.ukf.x_post

    @property
    def P_prior(self) -> np.ndarray:
        return self.ukf.P_prior

    @property
    def P_post(self) -> np.ndarray:
        return self.ukf.P_post

    #: The UKF has no fixed observer gains (see :attr:`K`).
    gains = None

    @property
    def K(self) -> np.ndarray:
        """Kalman gain of the last ``update``, shape (3,): it changes at every sample.

        Unlike the PHSO/ESO's fixed ``K``, this is filterpy's ``ukf.K[:, 0]``
        (zeros before the first update).
        """
        return np.array(self.ukf.K, dtype=float).reshape(3)

    def as_iosystem(self, name: str | None = None):
        """Not available: the UKF has no continuous-time form.

        Raises
        ------
        GainError
            Always; build a :class:`~bwdesign.observers.HysteresisObserver` or
            :class:`~bwdesign.observers.ExtendedStateObserver` from continuous
            gains for a python-control system.
        """
        raise GainError(
            "UnscentedObserver has no continuous form (its gain changes every sample): "
            "as_iosystem() exists only for HysteresisObserver and ExtendedStateObserver "
            "built from continuous gains"
        )

    @property
    def Q(self) -> np.ndarray:
        """Process noise covariance (3, 3)."""
        return self.ukf.Q

    @property
    def R(self) -> np.ndarray:
        """Measurement noise variance (1, 1)."""
        return self.ukf.R

    # -- filtering ---------------------------------------------------------
    def predict(self, u: float) -> None:
        """Propagate the sigma points one sample with ``u`` (V) held (exact plant step)."""
        u = finite_scalar(u, "u")
        require_finite_state(self.ukf.x, "UnscentedObserver")
        self.ukf.predict(u_prev=self.u_prev, u=u)
        self.u_prev = u

    def update(self, z: float | None) -> None:
        """Correct with ``z = y(t_{k+1})`` (length unit); ``None`` skips the sample."""
        if z is None:
            self.ukf.update(None)
            self.z, self.y = None, 0.0
            return
        z = finite_scalar(z, "z")
        require_finite_state(self.ukf.x, "UnscentedObserver")
        self.ukf.update(np.array([z]))
        self.z, self.y = z, float(self.ukf.y[0])

    def batch_filter(self, zs: Any, us: Any) -> np.ndarray:
        """Run ``predict(us[k])``, ``update(zs[k])`` over a record.

        Parameters
        ----------
        zs : sequence of float or None, length N
            ``zs[k] = y(t_{k+1})``; ``None`` marks a missing sample.
        us : array_like, shape (N,)
            Held inputs (V).

        Returns
        -------
        ndarray, shape (N, 3)
            Posterior estimates at ``t_1 .. t_N``.
        """
        ul = as_inputs(us)
        zl = as_measurements(zs, len(ul))
        out = np.empty((len(ul), 3))
        f = self.ukf
        if ul:
            require_finite_state(f.x, "UnscentedObserver")
        up = self.u_prev
        for k, (uk, zk) in enumerate(zip(ul, zl, strict=True)):
            f.predict(u_prev=up, u=uk)
            f.update(None if zk is None else np.array([zk]))
            out[k] = f.x
            up = uk
        if ul:
            self.u_prev = up
            self.z = zl[-1]
            self.y = 0.0 if zl[-1] is None else float(f.y[0])
        return out

    def __repr__(self) -> str:
        return (
            f"UnscentedObserver(plant={self.params.name or 'unnamed'!r}, dt={self.dt:g}, "
            f"udot_max={self.udot_max}, noise_std={self.noise_std:g}, "
            f"x={np.array2string(np.asarray(self.x), precision=6)})"
        )
