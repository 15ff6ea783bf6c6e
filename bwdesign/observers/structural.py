"""A sampled observer of the structural Bouc-Wen form (states y, y', z), filterpy-style.

The model copy (:mod:`bwdesign.model.structural`) with output injection, in
predict/update form like the piezo observers (:mod:`bwdesign.observers.base`)::

    predict(u):  x_prior = Phi(x_post, u)          (the model over one sample)
    update(z):   x_post  = x_prior + K (z - y_prior)

``Phi`` integrates the three-state model over one sample with ``substeps`` RK4
steps; the input is held over the sample, or (``u_next`` given) linear between the
two samples (``batch_filter`` also takes the record's band-limited interpolant). The
gains ``K`` place the poles of ``(I - K C) F`` at the radii asked for,
with ``F`` the zero-order-hold model linearised at z = 0 (hysteresis slope alpha):
``y'' = (u - c y' - k y - z)/m``, ``z' = alpha y'``.

No certificate: the hysteresis error of this form is driven by the *estimated*
velocity (``z' - zhat' = alpha e_v - beta gamma (|y'| z - |yhat'| zhat) - ...``), not
by a known input rate as in the piezo form, so the sector and sampled tiers
(docs/design.md, section "Certificates") do not apply; docs/guide/structural.md,
section "The structural Bouc-Wen form" says so and no command takes a structural stage's gains.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import GainError, InputError
from ..model.structural import StructuralParams, require_bounded_structural
from ..model.structural_sim import band_limited
from ..validate import DT, Range, integer, real
from .base import as_inputs, as_measurements, finite_scalar, state_vector

__all__ = ["StructuralObserver", "structural_gains"]

#: Supported number of RK4 steps per sample in the prediction.
SUBSTEPS = Range(1, 1024)


def _linear_model(p: StructuralParams, dt: float) -> np.ndarray:
    """The ZOH transition matrix of the model linearised at z = 0 (slope alpha)."""
    from scipy.linalg import expm

    a = np.array([[0.0, 1.0, 0.0], [-p.k / p.m, -p.c / p.m, -1.0 / p.m], [0.0, p.alpha, 0.0]])
    return expm(a * dt)


def structural_gains(p: StructuralParams, dt: float, bandwidth_hz: float) -> np.ndarray:
    """Gains ``K`` placing the poles of ``(I - K C) F`` at ``exp(-2 pi f dt)`` times 1, 0.9, 0.8.

    Raises
    ------
    GainError
        The poles cannot be placed (``F`` not observable from y at this dt).
    """
    from scipy.signal import place_poles

    real(bandwidth_hz, "bandwidth_hz (Hz)", within=Range(0.0, 0.5 / dt, lo_open=True))
    f = _linear_model(p, dt)
    c = np.array([[1.0, 0.0, 0.0]])
    r = math.exp(-2.0 * math.pi * bandwidth_hz * dt)
    poles = np.array([r, 0.9 * r, 0.8 * r])
    try:  # duality: eig(F - K C F) = eig(F^T - (C F)^T K^T)
        res = place_poles(f.T, (c @ f).T, poles)
    except ValueError as err:
        raise GainError(f"the structural observer's poles cannot be placed: {err}") from None
    return res.gain_matrix.reshape(3)


class StructuralObserver:
    """Copy-of-model observer of the structural form with output injection (module docstring).

    Parameters
    ----------
    params : StructuralParams
    dt : float
        Sample time (s).
    bandwidth_hz : float, optional
        Observer bandwidth; default the linear natural frequency
        ``sqrt((k + alpha)/m)/(2 pi)``, at most a fifth of the sample rate.
    K : array_like of 3, optional
        Discrete gains instead of ``bandwidth_hz``.
    substeps : int
        RK4 steps per sample in the prediction.

    Attributes
    ----------
    x, x_prior, x_post : ndarray, shape (3,)
        ``(y, y', z)`` estimates.
    y : float
        The last residual ``z - y_prior``.
    """

    def __init__(
        self,
        params: StructuralParams,
        dt: float,
        *,
        bandwidth_hz: float | None = None,
        K: Any = None,
        substeps: int = 4,
        allow_unbounded: bool = False,
    ):
        if not isinstance(params, StructuralParams):
            raise InputError(
                f"StructuralObserver: params must be StructuralParams, got {type(params).__name__}"
            )
        require_bounded_structural(params, allow_unbounded)
        self.params = params
        self.dt = real(dt, "dt (s)", within=DT)
        self.substeps = integer(substeps, "substeps", within=SUBSTEPS)
        if K is not None:
            self.K = state_vector(K, "K")
        else:
            if bandwidth_hz is None:
                fn = math.sqrt((params.k + params.alpha) / params.m) / (2 * math.pi)
                bandwidth_hz = min(fn, 0.2 / self.dt)
            self.K = structural_gains(params, self.dt, bandwidth_hz)
        self.reset()

    def reset(self, x0: Any = None) -> None:
        """Restart from ``x0`` (default rest)."""
        x = np.zeros(3) if x0 is None else state_vector(x0, "x0")
        self.x, self.x_prior, self.x_post = x.copy(), x.copy(), x.copy()
        self.y = 0.0

    def _rhs(self, y: float, v: float, z: float, u: float) -> tuple[float, float, float]:
        p = self.params
        az = abs(z)
        zn = az ** (p.nu - 1.0) if p.nu != 1.0 else 1.0
        dz = p.alpha * v - p.beta * (p.gamma * abs(v) * zn * z + p.delta * v * zn * az)
        return v, (u - p.c * v - p.k * y - z) / p.m, dz

    def predict(self, u: float, u_next: float | None = None) -> None:
        """Propagate the estimate over one sample: input ``u`` held, or linear to ``u_next``."""
        u0 = finite_scalar(u, "u")
        u1 = u0 if u_next is None else finite_scalar(u_next, "u_next")
        n = 2 * self.substeps
        self._propagate([u0 + (u1 - u0) * j / n for j in range(n + 1)])

    def _propagate(self, u_half: list[float]) -> None:
        """RK4 over one sample; ``u_half``: the input at the ``2 substeps + 1`` half steps."""
        y, v, z = (float(a) for a in self.x)
        h = self.dt / self.substeps
        for i in range(self.substeps):
            ua, um, ub = u_half[2 * i], u_half[2 * i + 1], u_half[2 * i + 2]
            k1 = self._rhs(y, v, z, ua)
            k2 = self._rhs(y + 0.5 * h * k1[0], v + 0.5 * h * k1[1], z + 0.5 * h * k1[2], um)
            k3 = self._rhs(y + 0.5 * h * k2[0], v + 0.5 * h * k2[1], z + 0.5 * h * k2[2], um)
            k4 = self._rhs(y + h * k3[0], v + h * k3[1], z + h * k3[2], ub)
            y += h / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v += h / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            z += h / 6.0 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        x = np.array([y, v, z])
        if not np.all(np.isfinite(x)):
            raise InputError("the structural observer's prediction is not finite; reset() it")
        self.x, self.x_prior = x, x.copy()

    def update(self, z: float | None) -> None:
        """Correct with the measured displacement ``z`` (None: a missing sample, no correction)."""
        if z is None:
            self.y = 0.0
            self.x_post = self.x.copy()
            return
        r = finite_scalar(z, "z") - self.x[0]
        self.y = r
        self.x = self.x + self.K * r
        self.x_post = self.x.copy()

    def batch_filter(self, zs: Any, us: Any, *, between: str = "band") -> np.ndarray:
        """Posterior estimates over a record: ``update(zs[k])`` then a prediction to ``t_{k+1}``.

        ``zs[k]``, ``us[k]``: y and u at ``t_k`` (point samples,
        :mod:`bwdesign.model.structural_sim`). ``between``: the input between samples,
        ``"band"`` the record's band-limited interpolant (offline: it uses the whole
        record), ``"linear"`` (needs only the next sample) or ``"hold"``. Returns shape
        (N, 3), row k the estimate at ``t_k`` after its measurement.
        """
        u = as_inputs(us)
        z = as_measurements(zs, len(u))
        if between not in ("band", "linear", "hold"):
            raise InputError(f'between must be "band", "linear" or "hold", got {between!r}')
        n = 2 * self.substeps
        fine = (
            band_limited(np.asarray(u), n, periodic=False).tolist()
            if between == "band" and len(u) > 1
            else None
        )
        out = np.empty((len(u), 3))
        for k in range(len(u)):
            self.update(z[k])
            out[k] = self.x
            if fine is not None and k + 1 < len(u):
                self._propagate(fine[n * k : n * k + n + 1])
            else:
                nxt = u[k + 1] if between != "hold" and k + 1 < len(u) else None
                self.predict(u[k], nxt)
        return out
