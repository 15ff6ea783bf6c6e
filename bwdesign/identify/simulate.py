"""The exact ZOH plant split for fitting: hysteresis loop, then a linear filter.

The hysteresis state depends on the input path only (Bouc-Wen is rate
independent), not on ``(x1, x2)``; the linear part is driven by
``a1 (K u_k - h_k)`` with ``K = a3/a1``. So one simulation is a scalar loop for
``h`` (:func:`hysteresis_path`, the closed form of
:func:`bwdesign.model.plant.hysteresis_increment` inlined) and a second-order
IIR filter for ``x1`` (:func:`linear_response`, scipy's ``lfilter`` on the
transfer function of the exact ZOH matrices of
:func:`bwdesign.model.plant.discretize`, in closed form). A fit changes the linear parameters
far more often than the hysteresis ones, and then only the cheap filter reruns.
``tests/test_identify_core.py`` checks both against
:func:`bwdesign.simulate_zoh` to 1e-10.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter, lfiltic

from ..model.params import BoucWenParams

__all__ = ["hysteresis_path", "linear_matrices", "linear_response", "simulate_output"]


def hysteresis_path(
    u: np.ndarray, h0: float, alpha: float, beta: float, gamma: float
) -> np.ndarray:
    """Hysteresis state after the jump at each sample, for a held input sequence.

    Parameters
    ----------
    u : ndarray, shape (N,)
        Held input (V); the input before ``t_0`` is taken as ``u[0]`` (no jump).
    h0 : float
        Hysteresis state at ``t_0`` (length unit).
    alpha, beta, gamma : float
        Bouc-Wen parameters with ``beta + gamma > 0`` and ``beta - gamma >= 0``.

    Returns
    -------
    ndarray, shape (N,)
        ``h[k]``: the state after the jump from ``u[k-1]`` to ``u[k]``.
    """
    cp = beta + gamma
    cm = beta - gamma
    out = np.empty(len(u))
    h = float(h0)
    up = float(u[0])
    exp, expm1, log1p = math.exp, math.expm1, math.log1p
    for k, uk in enumerate(u.tolist()):
        du = uk - up
        up = uk
        if du != 0.0:
            if du > 0.0:
                s, w, g = 1.0, du, h
            else:
                s, w, g = -1.0, -du, -h
            if g < 0.0:
                # branch c = beta - gamma until g crosses zero (at a distance wz)
                if cm == 0.0:
                    wz = -g / alpha
                else:
                    wz = log1p(-cm * g / alpha) / cm
                if w <= wz:
                    x = cm * w
                    if x < 1e-8:
                        g = g * (1.0 - x) + alpha * w * (1.0 - 0.5 * x)
                    else:
                        g = g * exp(-x) - alpha * expm1(-x) / cm
                    h = s * g
                    out[k] = h
                    continue
                g, w = 0.0, w - wz
            x = cp * w
            if x < 1e-8:
                g = g * (1.0 - x) + alpha * w * (1.0 - 0.5 * x)
            else:
                g = g * exp(-x) - alpha * expm1(-x) / cp
            h = s * g
        out[k] = h
    return out


def linear_matrices(a1: float, a2: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``Phi`` (2x2) and the unit-DC-gain input vector of the exact ZOH linear part.

    ``[x1, x2]_{k+1} = Phi [x1, x2]_k + b (K u_k - h_k)``, with ``b = a1 Gamma`` so
    that a constant drive ``w`` settles at ``x1 = w``. Closed form of the same
    matrix exponential as :func:`bwdesign.model.plant.discretize` (a fit needs
    it thousands of times): with ``mu = -a2/2`` and ``d^2 = a2^2/4 - a1``,
    ``expm(A dt) = e^{mu dt} (c I + s (A - mu I))``, ``c = cosh(d dt)``,
    ``s = sinh(d dt)/d`` (cos and sin for ``d^2 < 0``), and
    ``b = A^{-1} (Phi - I) [0, a1]``.
    """
    mu = -0.5 * a2
    d2 = 0.25 * a2 * a2 - a1
    q = d2 * dt * dt
    if abs(q) < 1e-8:  # near critical damping: series of cosh/cos and sinh/sin
        e = math.exp(mu * dt)
        ec, es = e * (1.0 + 0.5 * q), e * dt * (1.0 + q / 6.0)
    elif d2 > 0.0:
        # e^{(mu +- d) dt} separately: no overflow of cosh when heavily overdamped
        d = math.sqrt(d2)
        ep, em = math.exp((mu + d) * dt), math.exp((mu - d) * dt)
        ec, es = 0.5 * (ep + em), 0.5 * (ep - em) / d
    else:
        om = math.sqrt(-d2)
        e = math.exp(mu * dt)
        ec, es = e * math.cos(om * dt), e * math.sin(om * dt) / om
    h = 0.5 * a2 * es
    phi = np.array([[ec + h, es], [-a1 * es, ec - h]])
    return phi, np.array([1.0 - ec - h, a1 * es])


def linear_response(phi: np.ndarray, b: np.ndarray, w: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """``x1`` at ``t_1 .. t_N`` for the drive ``w`` (length unit) from state ``x0``.

    The state recursion written as its transfer function from ``w_k`` to
    ``x1_{k+1}``, ``(b1 + (p12 b2 - p22 b1) z^-1) / (1 - tr(Phi) z^-1 + det(Phi) z^-2)``,
    started exactly from the first two outputs.
    """
    n = len(w)
    y = np.empty(n)
    x1 = phi @ x0 + b * w[0]
    y[0] = x1[0]
    if n == 1:
        return y
    y[1] = (phi @ x1 + b * w[1])[0]
    if n == 2:
        return y
    # y[k] = x1(t_{k+1}) = tr y[k-1] - det y[k-2] + n1 w[k] + n2 w[k-1]
    num = np.array([b[0], phi[0, 1] * b[1] - phi[1, 1] * b[0]])
    den = np.array([1.0, -(phi[0, 0] + phi[1, 1]), phi[0, 0] * phi[1, 1] - phi[0, 1] * phi[1, 0]])
    zi = lfiltic(num, den, y=[y[1], y[0]], x=[w[1]])
    y[2:], _ = lfilter(num, den, w[2:], zi=zi)
    return y


def simulate_output(
    params: BoucWenParams, u: np.ndarray, dt: float, x0: np.ndarray, *, offset: float = 0.0
) -> np.ndarray:
    """Displacement at ``t_1 .. t_N`` (plus a sensor offset), as the fit computes it.

    Parameters
    ----------
    params : BoucWenParams
    u : ndarray, shape (N,)
        Held input (V), with ``u_prev = u[0]``.
    dt : float
        Sample time (s).
    x0 : array_like, shape (3,)
        State at ``t_0``.
    offset : float
        Added to every output (length unit).
    """
    u = np.asarray(u, dtype=float)
    x0 = np.asarray(x0, dtype=float)
    h = hysteresis_path(u, x0[2], params.alpha, params.beta, params.gamma)
    phi, b = linear_matrices(params.a1, params.a2, dt)
    return linear_response(phi, b, params.static_gain * u - h, x0[:2]) + offset
