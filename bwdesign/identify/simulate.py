"""The exact ZOH plant split for fitting: hysteresis loop, then a linear filter.

The hysteresis state depends on the input path only (Bouc-Wen is rate
independent), not on ``(x1, x2)``; the linear part is driven by
``a1 (K u_k - h_k)`` with ``K = a3/a1``. So one simulation is the hysteresis path
(:func:`hysteresis_path`: the closed form of
:func:`bwdesign.model.plant.hysteresis_increment` composed over each monotone run of
the input, one scalar pass over the runs and one vectorised pass over the samples;
:func:`hysteresis_sensitivity` adds its exact derivatives) and a second-order
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
from scipy.signal import lfilter

from ..model.params import BoucWenParams

__all__ = [
    "Segments",
    "hysteresis_path",
    "hysteresis_paths",
    "hysteresis_sensitivity",
    "linear_matrices",
    "linear_response",
    "simulate_output",
]


class Segments:
    """The monotone runs of a held input: the hysteresis recursion per run is closed-form.

    Bouc-Wen is rate independent and, on a run where the input moves one way, its
    state obeys ``dg/dw = alpha - c g`` in the travel ``w`` (``g = s h``, ``s`` the
    direction, ``c = beta + gamma`` while ``g >= 0``, ``beta - gamma`` before ``g``
    crosses zero): the steps of a run compose into one closed form of the travel
    since its start. Only the runs' end states need a sequential pass (a slow sine
    has two runs per period); every sample is then evaluated at once.
    """

    def __init__(self, u: np.ndarray):
        u = np.asarray(u, dtype=float)
        du = np.diff(u, prepend=u[0])
        sgn = np.sign(du)
        # sign of the last non-zero step at or before each sample (0 before the first)
        idx = np.maximum.accumulate(np.where(sgn != 0, np.arange(u.size), -1))
        last = np.where(idx >= 0, sgn[np.maximum(idx, 0)], 0.0)
        prev = np.concatenate(([0.0], last[:-1]))
        start = (sgn != 0) & (sgn != prev)
        start[0] = True
        self.starts = np.flatnonzero(start)
        self.seg = np.cumsum(start) - 1
        travel = np.cumsum(np.abs(du))
        base = travel[self.starts] - np.abs(du[self.starts])
        self.w = travel - base[self.seg]
        ends = np.concatenate((self.starts[1:] - 1, [u.size - 1]))
        self.w_end = self.w[ends]
        d = sgn[self.starts]
        self.s = np.where(d == 0, 1.0, d)


def _psi(x):
    """``-expm1(-x)/x`` (1 at 0) and its derivative, for arrays ``x >= 0``."""
    small = x < 1e-4
    xs = np.where(small, 1.0, x)
    em = np.expm1(-xs)
    psi = np.where(small, 1.0 - x / 2 + x * x / 6, -em / xs)
    dpsi = np.where(small, -0.5 + x / 3 - x * x / 8, (xs * (em + 1.0) + em) / (xs * xs))
    return psi, dpsi


def _psi1(x: float) -> tuple[float, float]:
    if x < 1e-4:
        return 1.0 - x / 2 + x * x / 6, -0.5 + x / 3 - x * x / 8
    em = math.expm1(-x)
    return -em / x, (x * (em + 1.0) + em) / (x * x)


def _phi1(y: float) -> tuple[float, float]:
    """``log1p(y)/y`` (1 at 0) and its derivative."""
    if y < 1e-4:
        return 1.0 - y / 2 + y * y / 3, -0.5 + 2 * y / 3 - 0.75 * y * y
    lp = math.log1p(y)
    return lp / y, (y / (1.0 + y) - lp) / (y * y)


def _run_end(g0, d0, w, cp, cm, alpha):
    """State (and its sensitivities to cp, cm, h0) after travelling ``w`` along one run."""
    if g0 < 0.0:
        m = -g0 / alpha
        ph, dph = _phi1(cm * m)
        wz = m * ph
        if w <= wz:
            x = cm * w
            ps, dps = _psi1(x)
            e = math.exp(-x)
            g = g0 * e + alpha * w * ps
            if d0 is None:
                return g, None
            fc = -w * g0 * e + alpha * w * w * dps
            return g, (e * d0[0], e * d0[1] + fc, e * d0[2])
        v = w - wz
        ps, dps = _psi1(cp * v)
        g = alpha * v * ps
        if d0 is None:
            return g, None
        fw = alpha * math.exp(-cp * v)
        # wz = m phi(cm m), m = -g0/alpha
        dwz_dg0 = -(ph + cm * m * dph) / alpha
        dwz_dcm = m * m * dph
        fc = alpha * v * v * dps
        return g, (
            -fw * dwz_dg0 * d0[0] + fc,
            -fw * (dwz_dg0 * d0[1] + dwz_dcm),
            -fw * dwz_dg0 * d0[2],
        )
    x = cp * w
    ps, dps = _psi1(x)
    e = math.exp(-x)
    g = g0 * e + alpha * w * ps
    if d0 is None:
        return g, None
    fc = -w * g0 * e + alpha * w * w * dps
    return g, (e * d0[0] + fc, e * d0[1], e * d0[2])


def _runs(seg: Segments, h0, cp, cm, alpha, sens):
    """Start state of every run (and its sensitivities), by one pass over the runs."""
    n = seg.starts.size
    g0 = np.empty(n)
    d0 = np.zeros((n, 3)) if sens else None
    h, dh = float(h0), ((0.0, 0.0, 1.0) if sens else None)
    s_list, w_list = seg.s.tolist(), seg.w_end.tolist()
    for j in range(n):
        s = s_list[j]
        g = s * h
        dg = (s * dh[0], s * dh[1], s * dh[2]) if sens else None
        g0[j] = g
        if sens:
            d0[j] = dg
        g, dg = _run_end(g, dg, w_list[j], cp, cm, alpha)
        h = s * g
        if sens:
            dh = (s * dg[0], s * dg[1], s * dg[2])
    return g0, d0


def _evaluate(seg: Segments, g0j, d0j, cp, cm, alpha, sens):
    """``h`` at every sample (and ``dh/d(cp, cm, h0)``) from the runs' start states."""
    g0 = g0j[seg.seg]
    s = seg.s[seg.seg]
    w = seg.w
    neg = g0 < 0.0
    m = np.where(neg, -g0 / alpha, 0.0)
    y = cm * m
    ys = np.where(y < 1e-4, 1.0, y)
    lp = np.log1p(ys)
    ph = np.where(y < 1e-4, 1.0 - y / 2 + y * y / 3, lp / ys)
    wz = m * ph
    before = neg & (w <= wz)  # still on the beta - gamma branch
    cross = neg & ~before
    c = np.where(before, cm, cp)
    v = np.where(cross, w - wz, w)
    gs = np.where(cross, 0.0, g0)
    x = c * v
    e = np.exp(-x)
    psi, dpsi = _psi(x)
    g = gs * e + alpha * v * psi
    h = s * g
    if not sens:
        return h, None
    d0 = d0j[seg.seg]
    fc = -v * gs * e + alpha * v * v * dpsi
    dph = np.where(y < 1e-4, -0.5 + 2 * y / 3 - 0.75 * y * y, (ys / (1.0 + ys) - lp) / (ys * ys))
    dwz_dg0 = -(ph + y * dph) / alpha
    dwz_dcm = m * m * dph
    fw = alpha * e
    d = np.empty((w.size, 3))
    # on a branch: e * d0 plus the branch constant's own term; after the crossing the
    # state depends on g0 and cm only through the crossing distance wz
    d[:, 0] = np.where(cross, -fw * dwz_dg0 * d0[:, 0], e * d0[:, 0]) + np.where(before, 0.0, fc)
    d[:, 1] = np.where(cross, -fw * (dwz_dg0 * d0[:, 1] + dwz_dcm), e * d0[:, 1]) + np.where(
        before, fc, 0.0
    )
    d[:, 2] = np.where(cross, -fw * dwz_dg0 * d0[:, 2], e * d0[:, 2])
    return h, d * s[:, None]


def hysteresis_path(
    u: np.ndarray,
    h0: float,
    alpha: float,
    beta: float,
    gamma: float,
    *,
    segments: Segments | None = None,
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
    segments : Segments, optional
        ``Segments(u)``, when the same input is simulated many times.

    Returns
    -------
    ndarray, shape (N,)
        ``h[k]``: the state after the jump from ``u[k-1]`` to ``u[k]``.
    """
    seg = segments if segments is not None else Segments(u)
    cp, cm = beta + gamma, beta - gamma
    g0, _ = _runs(seg, h0, cp, cm, alpha, False)
    return _evaluate(seg, g0, None, cp, cm, alpha, False)[0]


def _advance(g0, w, cp, cm, alpha):
    """:func:`_run_end` without sensitivities, for arrays (``w`` broadcasts against ``g0``).

    On a branch of constant ``c`` the state after travel ``v`` is
    ``g e^{-cv} - alpha expm1(-cv)/c`` (``alpha v`` at ``c = 0``).
    """
    neg = g0 < 0.0
    m = np.where(neg, -g0 / alpha, 0.0)
    y = cm * m
    ys = np.where(y < 1e-4, 1.0, y)
    wz = m * np.where(y < 1e-4, 1.0 - y / 2 + y * y / 3, np.log1p(ys) / ys)
    cross = neg & (w > wz)
    c = np.where(neg & ~cross, cm, cp)
    v = np.where(cross, w - wz, w)
    em = np.expm1(-c * v)
    rise = np.divide(-alpha * em, c, out=alpha * v * np.ones_like(em), where=c > 0)
    return np.where(cross, 0.0, g0) * (em + 1.0) + rise


def hysteresis_paths(
    segments: Segments, h0: np.ndarray, alpha: float, cp: np.ndarray, cm: np.ndarray
) -> np.ndarray:
    """:func:`hysteresis_path` for several parameter sets at once (a start grid).

    ``h0``, ``cp = beta + gamma`` and ``cm = beta - gamma`` are arrays of one
    length ``G``; returns ``(N, G)``, column ``g`` the path of set ``g`` (equal to
    :func:`hysteresis_path` to rounding). One pass over the runs for all sets.
    """
    h = np.array(h0, dtype=float)
    cp = np.asarray(cp, dtype=float)
    cm = np.asarray(cm, dtype=float)
    g0 = np.empty((segments.starts.size, h.size))
    for j, (s, w) in enumerate(zip(segments.s.tolist(), segments.w_end.tolist(), strict=True)):
        g = s * h
        g0[j] = g
        h = s * _advance(g, w, cp, cm, alpha)
    # every sample from its run's start state and the travel since
    return segments.s[segments.seg, None] * _advance(
        g0[segments.seg], segments.w[:, None], cp, cm, alpha
    )


def hysteresis_sensitivity(
    segments: Segments, h0: float, alpha: float, beta: float, gamma: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`hysteresis_path` and its exact derivatives (forward mode along the runs).

    Returns ``h`` (N,) and ``dh`` (N, 3): the derivatives with respect to
    ``beta + gamma``, ``beta - gamma`` and ``h0`` (alpha held).
    """
    cp, cm = beta + gamma, beta - gamma
    g0, d0 = _runs(segments, h0, cp, cm, alpha, True)
    return _evaluate(segments, g0, d0, cp, cm, alpha, True)


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
    started exactly from the first two outputs. ``w`` may be ``(N, m)`` with ``x0``
    ``(2, m)``: ``m`` responses in one filter call (the columns of a Jacobian).
    """
    w = np.asarray(w, dtype=float)
    x0 = np.asarray(x0, dtype=float)
    n = len(w)
    y = np.empty(w.shape)
    x1 = phi @ x0 + np.multiply.outer(b, w[0])
    y[0] = x1[0]
    if n == 1:
        return y
    y[1] = (phi @ x1 + np.multiply.outer(b, w[1]))[0]
    if n == 2:
        return y
    # y[k] = x1(t_{k+1}) = tr y[k-1] - det y[k-2] + n1 w[k] + n2 w[k-1]
    n1, n2 = b[0], phi[0, 1] * b[1] - phi[1, 1] * b[0]
    d1 = -(phi[0, 0] + phi[1, 1])
    d2 = phi[0, 0] * phi[1, 1] - phi[0, 1] * phi[1, 0]
    # the transposed direct form's state that continues from y[1], y[0] (as lfiltic)
    zi = np.array([n2 * w[1] - d1 * y[1] - d2 * y[0], -d2 * y[1]])
    y[2:], _ = lfilter([n1, n2], [1.0, d1, d2], w[2:], axis=0, zi=zi)
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
