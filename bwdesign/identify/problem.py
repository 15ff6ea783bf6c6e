"""The output-error problem in scaled, identifiable coordinates.

Fit vector ``theta`` (all O(1)):

=====  ==============  =====================================================
index  name            meaning
=====  ==============  =====================================================
0      log_gain        ``log |K|``, ``K = a3/a1`` the static gain (µm/V)
1      log_lag         ``log tau``, ``tau = a2/a1`` (s): the low-frequency lag
2      log_wn          ``log wn``, ``wn = sqrt(a1)`` (rad/s): the resonance
3      log_alpha       ``log alpha``
4      log_beta        ``log beta``
5      shape           ``q``, ``gamma = beta tanh(q)``
6      offset          sensor offset, ``y_mean + y_scale * theta``
7      h0              initial hysteresis state, ``theta * alpha/(beta + gamma)``
8      x1_0            initial displacement minus its equilibrium, in ``y_scale``
9      x2_0            initial velocity in ``y_scale * wn``
=====  ==============  =====================================================

``alpha > 0``, ``beta > 0`` and ``beta - gamma = beta (1 - tanh q) > 0``,
``beta + gamma > 0``: every ``theta`` is in the bounded class (an open set; its
boundary ``beta = gamma`` is approached only as ``q -> inf``).
"""

from __future__ import annotations

import math

import numpy as np

from ..model.params import A3_MAGNITUDE, PARAM_RANGES, BoucWenParams
from .simulate import (
    Segments,
    hysteresis_path,
    hysteresis_paths,
    hysteresis_sensitivity,
    linear_matrices,
    linear_response,
)

__all__ = ["FIT_NAMES", "Problem", "params_from_theta", "theta_from_params"]

FIT_NAMES = (
    "log_gain",
    "log_lag",
    "log_wn",
    "log_alpha",
    "log_beta",
    "shape",
    "offset",
    "h0",
    "x1_0",
    "x2_0",
)
IK, ITAU, IW, IA, IB, IQ, IOFF, IZ, IE1, IE2 = range(10)
#: Largest |q|: tanh(8) = 1 - 2.3e-7 keeps beta - gamma > 0 in floating point.
Q_MAX = 8.0


def params_from_theta(theta: np.ndarray, sign: float, name: str = "") -> BoucWenParams:
    """The Bouc-Wen parameters of a fit vector."""
    wn2 = _clip(math.exp(min(2.0 * theta[IW], 700.0)), "a1")
    a3 = _clip(math.exp(min(theta[IK], 700.0)) * wn2, "a3", magnitude=True)
    beta = _clip(math.exp(min(theta[IB], 700.0)), "beta")
    return BoucWenParams(
        a1=wn2,
        a2=_clip(math.exp(min(theta[ITAU], 700.0)) * wn2, "a2"),
        a3=sign * a3,
        alpha=_clip(math.exp(min(theta[IA], 700.0)), "alpha"),
        beta=beta,
        gamma=beta * math.tanh(theta[IQ]),
        name=name,
    )


def _clip(value: float, name: str, *, magnitude: bool = False) -> float:
    """``value`` held inside the package's supported range of ``name``.

    Far outside the data's reach a fit vector may ask for, e.g., a1 = 1e18; the
    parameters are clipped to :data:`bwdesign.model.params.PARAM_RANGES` (where
    the fit is flat, so the optimiser turns back) instead of being refused.
    """
    r = A3_MAGNITUDE if magnitude else PARAM_RANGES[name]
    return min(max(value, r.lo), r.hi)


def theta_from_params(p: BoucWenParams) -> tuple[np.ndarray, float]:
    """The first six fit coordinates of a bounded parameter set, and the gain's sign."""
    beta = p.beta
    ratio = min(max(p.gamma / beta, -math.tanh(Q_MAX)), math.tanh(Q_MAX)) if beta > 0 else 0.0
    th = np.zeros(10)
    th[IK] = math.log(abs(p.static_gain))
    th[ITAU] = math.log(max(p.a2, 1e-12 * math.sqrt(p.a1)) / p.a1)
    th[IW] = 0.5 * math.log(p.a1)
    th[IA] = math.log(p.alpha)
    th[IB] = math.log(beta) if beta > 0 else 0.0
    th[IQ] = math.atanh(ratio)
    return th, math.copysign(1.0, p.a3)


def delayed_input(u: np.ndarray, d: int) -> np.ndarray:
    """The held input delayed by ``d`` samples (the first value held before the record)."""
    if d == 0:
        return u
    return np.concatenate((np.full(d, u[0]), u[:-d]))


class Problem:
    """Residuals and Jacobian of one record for a fixed input delay.

    Parameters
    ----------
    u : ndarray
        Held input (V), already delayed.
    y : ndarray
        Measured output (µm).
    dt : float
        Sample time (s).
    sign : float
        Sign of the static gain.
    y_scale : float, optional
        Output scale of the residual (default: the standard deviation of ``y``;
        records fitted together share one, :class:`bwdesign.identify.stack.Stack`).
    """

    def __init__(
        self, u: np.ndarray, y: np.ndarray, dt: float, sign: float, *, y_scale: float | None = None
    ):
        self.u = np.ascontiguousarray(u, dtype=float)
        self.y = np.ascontiguousarray(y, dtype=float)
        self.dt = float(dt)
        self.sign = float(sign)
        self.y_mean = float(np.mean(y))
        self.y_scale = float(y_scale) if y_scale is not None else (float(np.std(y)) or 1.0)
        self.segments = Segments(self.u)
        self._cache: dict[tuple[float, float, float], np.ndarray] = {}
        self._sens: tuple[tuple[float, float, float], np.ndarray, np.ndarray] | None = None
        # responses that do not depend on the hysteresis path, for the last (lag, resonance)
        self._fixed: tuple[tuple[float, float], np.ndarray] | None = None
        self.n_loops = 0

    # -- model --------------------------------------------------------------
    def unit_hysteresis(self, theta: np.ndarray) -> np.ndarray:
        """Hysteresis path for ``alpha = 1`` (h scales with alpha at fixed ``h0/alpha``)."""
        key = (float(theta[IB]), float(theta[IQ]), float(theta[IZ]))
        h = self._cache.get(key)
        if h is None:
            beta = math.exp(key[0])
            gamma = beta * math.tanh(key[1])
            h = hysteresis_path(
                self.u, key[2] / (beta + gamma), 1.0, beta, gamma, segments=self.segments
            )
            self.n_loops += 1
            if len(self._cache) >= 16:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = h
        return h

    def predict(self, theta: np.ndarray) -> np.ndarray:
        """Model output at the measurement instants (µm)."""
        k = self.sign * math.exp(theta[IK])
        wn = math.exp(theta[IW])
        phi, b = linear_matrices(wn * wn, math.exp(theta[ITAU]) * wn * wn, self.dt)
        w = k * self.u - math.exp(theta[IA]) * self.unit_hysteresis(theta)
        x0 = np.array([w[0] + self.y_scale * theta[IE1], self.y_scale * wn * theta[IE2]])
        return linear_response(phi, b, w, x0) + (self.y_mean + self.y_scale * theta[IOFF])

    def residual(self, theta: np.ndarray) -> np.ndarray:
        """Scaled residual ``(model - measured) / y_scale``."""
        return (self.predict(theta) - self.y) / self.y_scale

    def unit_sensitivity(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit hysteresis path and its derivatives in (log_beta, shape, h0), exactly."""
        key = (float(theta[IB]), float(theta[IQ]), float(theta[IZ]))
        if self._sens is not None and self._sens[0] == key:
            return self._sens[1], self._sens[2]
        beta = math.exp(key[0])
        t = math.tanh(key[1])
        cp, cm = beta * (1.0 + t), beta * (1.0 - t)
        h0 = key[2] / cp
        h, d = hysteresis_sensitivity(self.segments, h0, 1.0, beta, beta * t)
        self.n_loops += 1
        sech2 = 1.0 - t * t
        # h0 = z / cp: the derivatives reach h through cp as well as through h0
        out = np.empty_like(d)
        out[:, 0] = d[:, 0] * cp + d[:, 1] * cm - d[:, 2] * h0
        out[:, 1] = beta * sech2 * (d[:, 0] - d[:, 1] - d[:, 2] * h0 / cp)
        out[:, 2] = d[:, 2] / cp
        self._sens = (key, h, out)
        return h, out

    def jacobian(self, theta: np.ndarray, free: np.ndarray, *, central: bool = False) -> np.ndarray:
        """Jacobian of :meth:`residual` in the ``free`` coordinates.

        Exact for gain, alpha, the hysteresis shape (forward-mode sensitivities along
        the input's runs, :func:`bwdesign.identify.simulate.hysteresis_sensitivity`),
        offset and initial state: one pass and one batched filter call. The lag and
        the resonance change only the linear filter: central differences of the
        filter alone (no hysteresis rerun). ``central`` is accepted for compatibility.
        """
        del central
        n = self.u.size
        wn = math.exp(theta[IW])
        phi, b = linear_matrices(wn * wn, math.exp(theta[ITAU]) * wn * wn, self.dt)
        k = self.sign * math.exp(theta[IK])
        alpha = math.exp(theta[IA])
        h, dh = self.unit_sensitivity(theta)
        cols = np.zeros((n, 10))
        drive = np.column_stack([k * self.u, -alpha * h, -alpha * dh, np.zeros((n, 2))])
        x0 = np.zeros((2, 7))
        x0[0, :5] = drive[0, :5]
        x0[0, 5], x0[1, 6] = 1.0, wn
        resp = linear_response(phi, b, drive, x0)
        cols[:, IK], cols[:, IA] = resp[:, 0], resp[:, 1]
        cols[:, IB], cols[:, IQ], cols[:, IZ] = resp[:, 2], resp[:, 3], resp[:, 4]
        cols[:, IE1], cols[:, IE2] = resp[:, 5], resp[:, 6]
        cols[:, :IOFF] /= self.y_scale
        cols[:, IZ] /= self.y_scale
        cols[:, IOFF] = 1.0
        for i in (ITAU, IW):
            if free[i]:
                step = 1e-5
                tp, tm = theta.copy(), theta.copy()
                tp[i] += step
                tm[i] -= step
                cols[:, i] = (self.predict(tp) - self.predict(tm)) / (2 * step * self.y_scale)
        return cols[:, free]

    # -- linear sub-problem (variable projection, for start values) ----------
    def linear_basis(self, theta: np.ndarray, h_unit: np.ndarray) -> np.ndarray:
        """Columns whose coefficients are K, alpha, offset, x1_0 and x2_0 deviations.

        The gain and initial-state columns depend on the lag and resonance only: they
        are kept for the last (lag, resonance), so a grid over the hysteresis shape
        filters one column per point (the same numbers as filtering all five).
        """
        key = (float(theta[IW]), float(theta[ITAU]))
        wn = math.exp(theta[IW])
        phi, b = linear_matrices(wn * wn, math.exp(theta[ITAU]) * wn * wn, self.dt)
        if self._fixed is None or self._fixed[0] != key:
            zero = np.zeros_like(self.u)
            drive = np.column_stack([self.sign * self.u, zero, zero])
            x0 = np.array([[self.sign * self.u[0], 1.0, 0.0], [0.0, 0.0, wn]])
            self._fixed = (key, linear_response(phi, b, drive, x0))
        fixed = self._fixed[1]
        h_resp = linear_response(phi, b, -h_unit, np.array([-h_unit[0], 0.0]))
        return np.column_stack([fixed[:, 0], h_resp, np.ones_like(self.u), fixed[:, 1:]])

    def project(
        self, theta: np.ndarray, h_unit: np.ndarray | None = None
    ) -> tuple[float, np.ndarray]:
        """Best linear coefficients for the nonlinear part of ``theta``.

        Returns the sum of squared scaled residuals and ``theta`` with gain,
        alpha, offset and initial state filled in (``inf`` when the best alpha
        or gain is not positive).
        """
        if h_unit is None:
            h_unit = self.unit_hysteresis(theta)
        basis = self.linear_basis(theta, h_unit)
        coef, *_ = np.linalg.lstsq(basis, self.y, rcond=None)
        if coef[0] <= 0 or coef[1] <= 0:
            return math.inf, theta.copy()
        r = basis @ coef - self.y
        return float(r @ r) / self.y_scale**2, self._filled(theta, coef)

    def _filled(self, theta: np.ndarray, coef: np.ndarray) -> np.ndarray:
        """``theta`` with the linear coefficients (K, alpha, offset, x1_0, x2_0) set."""
        th = theta.copy()
        th[IK] = math.log(coef[0])
        th[IA] = math.log(coef[1])
        th[IOFF] = (coef[2] - self.y_mean) / self.y_scale
        # basis columns 3, 4 are responses to unit x1 and x2/wn deviations
        th[IE1] = coef[3] / self.y_scale
        th[IE2] = coef[4] / self.y_scale
        return th

    def project_many(self, thetas: list[np.ndarray]) -> list[tuple[float, np.ndarray]]:
        """:meth:`project` for several hysteresis shapes at one lag and resonance (a grid).

        The paths are computed together (:func:`hysteresis_paths`) and filtered in one
        call; the gain and initial-state columns are shared, so each point's least
        squares is one column projected against their QR factor. The same minimiser as
        :meth:`project` to rounding (which it falls back to when those columns are
        nearly dependent).
        """
        if len({(float(t[IW]), float(t[ITAU])) for t in thetas}) != 1:
            return [self.project(t) for t in thetas]
        th0 = thetas[0]
        beta = np.exp([float(t[IB]) for t in thetas])
        gamma = beta * np.tanh([float(t[IQ]) for t in thetas])
        cp, cm = beta + gamma, beta - gamma
        h = hysteresis_paths(self.segments, np.array([t[IZ] for t in thetas]) / cp, 1.0, cp, cm)
        self.n_loops += len(thetas)
        self.linear_basis(th0, h[:, 0])  # the shared columns for this lag and resonance
        fixed = self._fixed[1]
        shared = np.column_stack([fixed[:, 0], np.ones_like(self.u), fixed[:, 1:]])
        q, r_f = np.linalg.qr(shared)
        # a column within rounding of the ones before it (the two initial-state
        # responses with the resonance held far above the record) gets coefficient 0
        keep = np.abs(np.diag(r_f)) > 1e-10 * np.linalg.norm(shared, axis=0)
        if not keep[:2].all():
            return [self.project(t) for t in thetas]
        if not keep.all():
            q, r_f = np.linalg.qr(shared[:, keep])
        wn = math.exp(th0[IW])
        phi, b = linear_matrices(wn * wn, math.exp(th0[ITAU]) * wn * wn, self.dt)
        resp = linear_response(phi, b, -h, np.vstack([-h[0], np.zeros(h.shape[1])]))
        qy = q.T @ self.y
        y_perp = self.y - q @ qy
        q_resp = q.T @ resp
        perp = resp - q @ q_resp
        norm2 = np.einsum("ij,ij->j", perp, perp)
        c_h = np.divide(perp.T @ y_perp, norm2, out=np.zeros_like(norm2), where=norm2 > 0)
        resid = y_perp[:, None] - perp * c_h
        cost = np.einsum("ij,ij->j", resid, resid) / self.y_scale**2
        c_f = np.zeros((4, len(thetas)))  # K, offset, x1_0, x2_0
        c_f[keep] = np.linalg.solve(r_f, qy[:, None] - q_resp * c_h)
        out = []
        for g, t in enumerate(thetas):
            coef = np.array([c_f[0, g], c_h[g], c_f[1, g], c_f[2, g], c_f[3, g]])
            if coef[0] <= 0 or coef[1] <= 0:
                out.append((math.inf, t.copy()))
            else:
                out.append((float(cost[g]), self._filled(t, coef)))
        return out
