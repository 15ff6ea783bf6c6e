"""The structural form's nu = 1 integrator, compiled (numba): the same operations, no interpreter.

:func:`bwdesign.model.structural_sim` integrates ``m y'' = u - c y' - k y - Z(y)`` with
RK4 on the fine input grid, each step split at a velocity reversal or a zero crossing of
z (located on the step's cubic Hermite interpolant), z in closed form along each
monotone stroke. Written in Python that is about 4 us a sub-step: an identification on
the hysteretic benchmark's 8192-sample records spends 12 s there. :func:`rk4_nu1` is
``structural_sim._rk4_nu1`` written once more for numba, operation for operation in the
same order (the closures become a stroke's constants, ``s**3`` stays libm's ``pow``,
``round`` a floor): the same floats to the bit (tested), about 50 times faster.
The compiled code is cached beside this file (``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["rk4_nu1"]

#: Points of the Lagrange interpolant between fine-grid inputs (structural_sim._LAGRANGE).
_LAGRANGE = 8


@njit(cache=True)
def _z(alpha, c, ya, za, y):
    """z on a stroke (structural_sim._piece's ``z_of``)."""
    d = y - ya
    x = -c * d
    if abs(x) < 1e-5:
        phi1 = 1.0 + x * (0.5 + x * (1.0 / 6.0 + x / 24.0))
    elif x > 700.0:
        return math.inf
    else:
        phi1 = math.expm1(x) / x
    return za * math.exp(x) + alpha * d * phi1


@njit(cache=True)
def _branch(alpha, b1, b2, sigma, ya, za):
    """structural_sim._branch: ``(c, ya, za, y_cross, has_after, c_after)``."""
    s0 = math.copysign(1.0, za) if za != 0.0 else sigma
    c0 = b1 * sigma + b2 * s0
    if s0 != sigma and 1.0 - c0 * za / alpha > 0.0:
        yc = ya + (math.log1p(-c0 * za / alpha) / c0 if c0 != 0.0 else -za / alpha)
        return c0, ya, za, yc, True, b1 * sigma + b2 * sigma
    return c0, ya, za, math.inf * sigma, False, 0.0


@njit(cache=True)
def _lagrange(grid, spacing, t):
    j = int(math.floor(t / spacing))
    j0 = min(max(j - _LAGRANGE // 2 + 1, 0), grid.shape[0] - _LAGRANGE)
    x = t / spacing
    total = 0.0
    for i in range(j0, j0 + _LAGRANGE):
        w = 1.0
        for m in range(j0, j0 + _LAGRANGE):
            if m != i:
                w *= (x - m) / (i - m)
        total += w * grid[i]
    return total


@njit(cache=True)
def _u_at(fine, half, t):
    on_grid = t / half
    k = math.floor(on_grid + 0.5)  # round(): only used within 1e-9 of an integer
    if abs(on_grid - k) < 1e-9:
        return fine[int(k)]
    return _lagrange(fine, half, t)


@njit(cache=True)
def _hermite_root(v0, d0, v1, d1):
    s = 0.0
    flo = (
        (2 * s**3.0 - 3 * s**2.0 + 1) * v0
        + (s**3.0 - 2 * s**2.0 + s) * d0
        + (-2 * s**3.0 + 3 * s**2.0) * v1
        + (s**3.0 - s**2.0) * d1
    )
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        s2, s3 = mid**2.0, mid**3.0
        fm = (
            (2 * s3 - 3 * s2 + 1) * v0
            + (s3 - 2 * s2 + mid) * d0
            + (-2 * s3 + 3 * s2) * v1
            + (s3 - s2) * d1
        )
        if (fm < 0.0) == (flo < 0.0):
            lo, flo = mid, fm
        else:
            hi = mid
        if hi - lo < 1e-15:
            break
    return min(max(0.5 * (lo + hi), 1e-12), 1.0 - 1e-12)


@njit(cache=True)
def _step(c, k, inv_m, alpha, zc, zya, zza, y, v, hh, u0, um, u1):
    a1 = (u0 - c * v - k * y - _z(alpha, zc, zya, zza, y)) * inv_m
    y2, v2 = y + 0.5 * hh * v, v + 0.5 * hh * a1
    a2 = (um - c * v2 - k * y2 - _z(alpha, zc, zya, zza, y2)) * inv_m
    y3, v3 = y + 0.5 * hh * v2, v + 0.5 * hh * a2
    a3 = (um - c * v3 - k * y3 - _z(alpha, zc, zya, zza, y3)) * inv_m
    y4, v4 = y + hh * v3, v + hh * a3
    a4 = (u1 - c * v4 - k * y4 - _z(alpha, zc, zya, zza, y4)) * inv_m
    yn = y + hh / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
    vn = v + hh / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    return yn, vn, a1


@njit(cache=True)
def _run(pars, fine, h, steps_per_sample, total, y, v, z, ys, vs, zs):
    """The loop of structural_sim._rk4_nu1; returns ``(code, step)``: 0 done, 1 more than 8
    events in the step, 2 diverged there."""
    m, c, k, alpha = pars[0], pars[1], pars[2], pars[3]
    beta, gamma, delta = pars[4], pars[5], pars[6]
    inv_m = 1.0 / m
    b1, b2 = beta * gamma, beta * delta
    a0 = (fine[0] - c * v - k * y - z) * inv_m
    if v != 0.0:
        sigma = math.copysign(1.0, v)
    else:
        sigma = math.copysign(1.0, a0) if a0 != 0.0 else 1.0
    zc, zya, zza, yc, after, ca = _branch(alpha, b1, b2, sigma, y, z)
    half = 0.5 * h
    for j in range(total):
        if j % steps_per_sample == 0:
            i = j // steps_per_sample
            ys[i], vs[i], zs[i] = y, v, _z(alpha, zc, zya, zza, y)
        t, t_end = j * h, (j + 1) * h
        ua = fine[2 * j]
        done = False
        for _ in range(8):  # sub-steps: at most a few events per step
            hh = t_end - t
            um = fine[2 * j + 1] if t == j * h else _u_at(fine, half, t + 0.5 * hh)
            u1 = fine[2 * j + 2]
            yn, vn, a_s = _step(c, k, inv_m, alpha, zc, zya, zza, y, v, hh, ua, um, u1)
            rev = vn * sigma < 0.0
            cross = after and sigma * (yn - yc) > 0.0
            if not (rev or cross):
                y, v = yn, vn
                done = True
                break
            if rev:
                a_e = (u1 - c * vn - k * yn - _z(alpha, zc, zya, zza, yn)) * inv_m
                th_rev = _hermite_root(v, a_s * hh, vn, a_e * hh)
            else:
                th_rev = 2.0
            th_cr = _hermite_root(y - yc, v * hh, yn - yc, vn * hh) if cross else 2.0
            th = min(th_rev, th_cr) * hh
            ue = _u_at(fine, half, t + th)
            um = _u_at(fine, half, t + 0.5 * th)
            y, v, _ = _step(c, k, inv_m, alpha, zc, zya, zza, y, v, th, ua, um, ue)
            t, ua = t + th, ue
            if th_rev < th_cr:
                sigma = -sigma
                zc, zya, zza, yc, after, ca = _branch(
                    alpha, b1, b2, sigma, y, _z(alpha, zc, zya, zza, y)
                )
            else:
                zc, zya, zza = ca, yc, 0.0
                yc, after = math.inf * sigma, False
        if not done:
            return 1, j, t
        if not (math.isfinite(y) and math.isfinite(v)):
            return 2, j, t
    n = ys.shape[0]
    ys[n - 1], vs[n - 1], zs[n - 1] = y, v, _z(alpha, zc, zya, zza, y)
    return 0, total, 0.0


def rk4_nu1(pars, fine, h, steps_per_sample, total, x0):
    """``(code, step, t, ys, vs, zs)``: structural_sim._rk4_nu1 compiled.

    ``pars`` = (m, c, k, alpha, beta, gamma, delta); ``code`` 0 done, 1 more than 8
    events within the integration step ``step`` (at time ``t``), 2 diverged in it.
    """
    n = total // steps_per_sample + 1
    ys, vs, zs = np.empty(n), np.empty(n), np.empty(n)
    y, v, z = (float(a) for a in x0)
    p = np.asarray(pars, dtype=float)
    g = np.ascontiguousarray(fine, dtype=float)
    code, step, t = _run(p, g, float(h), int(steps_per_sample), int(total), y, v, z, ys, vs, zs)
    return code, step, t, ys, vs, zs
