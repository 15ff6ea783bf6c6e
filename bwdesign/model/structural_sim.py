"""Simulation of the structural Bouc-Wen form (:mod:`bwdesign.model.structural`) on sampled inputs.

Sample convention: ``u[k]`` and ``y[k]`` are the values of a band-limited input and
of the displacement at ``t_k = k dt`` (point samples, as the hysteretic benchmark's
records are; not the piezo form's zero-order hold). Between samples the input is
the band-limited (Fourier) interpolant of its samples (:func:`band_limited`): exact
for a periodic record (one period, ``periodic=True``) of an input with no content at
or above the Nyquist frequency; a non-periodic record is extended by odd reflection (after
removing the line through its end samples) first, which keeps the interpolant band
limited away from the ends.

Two integrators, each with a stated order and an error estimate:

* ``nu = 1`` (the fast path, :func:`simulate_structural` with ``method="rk4"``). On
  every monotone stroke z is a closed-form function of y (the z equation is linear
  in z there: ``z = z_a e^{-c (y - y_a)} + alpha (1 - e^{-c (y - y_a)})/c``, with one
  switch of c where z crosses zero, located exactly), so the model reduces to the
  second-order ODE ``m y'' = u - c y' - k y - Z(y)``. It is integrated with the
  classical fourth-order Runge-Kutta method at ``upsample`` steps per sample;
  velocity reversals (where Z changes branch) are located on the step's cubic
  Hermite interpolant and the step is split there, so the solution is C^3 on every
  step and the global error is O(h^4). ``rtol`` turns on error control: the
  upsampling factor is doubled until the step-doubling estimate
  ``max |y_r - y_2r| / 15`` is below ``rtol max |y|`` (reported as ``error_estimate``).
* any ``nu`` (``method="dop853"``): the three-state ODE in (y, y', z) with scipy's
  adaptive eighth-order Dormand-Prince method (local error control at ``rtol``,
  ``atol`` = ``rtol`` times the state scale) and its dense output at the samples.

:func:`steady_state` simulates a periodic input period after period until the
state at the end of a period is within ``tol`` of the state at its start.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, SolverError
from ..validate import DT, Range, integer, real
from .structural import StructuralParams, require_bounded_structural

__all__ = [
    "StructuralRun",
    "band_limited",
    "simulate_structural",
    "simulate_batch",
    "steady_state",
    "UPSAMPLE",
]

#: Supported upsampling factor (integration steps per sample).
UPSAMPLE = Range(1, 4096)
#: Points of the Lagrange interpolant of the fine input grid at off-grid times.
_LAGRANGE = 8


@dataclass(frozen=True, eq=False)
class StructuralRun:
    """One simulated record.

    Attributes
    ----------
    y, v, z : ndarray, shape (N,)
        Displacement, velocity and hysteretic force at the samples ``t_k = k dt``.
    state : ndarray, shape (3,)
        ``(y, y', z)`` at ``t_N`` (where a next record would start).
    upsample : int
        Integration steps per sample used.
    error_estimate : float or None
        Step-doubling estimate of ``max |y - y_exact|`` (length unit), when asked for.
    periods : int
        Periods simulated (steady state), 1 otherwise.
    """

    y: np.ndarray
    v: np.ndarray
    z: np.ndarray
    state: np.ndarray
    upsample: int
    error_estimate: float | None = None
    periods: int = 1


def band_limited(u: np.ndarray, factor: int, *, periodic: bool) -> np.ndarray:
    """The band-limited interpolant of ``u`` at ``factor`` points per sample.

    Returns ``factor * N`` values at ``t = j dt / factor`` (periodic: one period) or
    ``factor * (N - 1) + 1`` values from ``t_0`` to ``t_{N-1}`` (non-periodic: the line
    through the two end samples plus the rest, extended oddly about both ends, so the
    extension is continuous with its first derivative, interpolated as one period).
    """
    u = np.asarray(u, dtype=float)
    if not periodic:  # the line through the ends, plus the rest reflected oddly at both ends
        n = u.size
        line = u[0] + (u[-1] - u[0]) * np.arange(n) / (n - 1)
        v = u - line
        fine = band_limited(np.concatenate([v, -v[-2:0:-1]]), factor, periodic=True)
        m = factor * (n - 1) + 1
        return fine[:m] + u[0] + (u[-1] - u[0]) * np.arange(m) / (m - 1)
    n = u.size
    spec = np.fft.rfft(u)
    if n % 2 == 0:  # the Nyquist line is shared by +-fs/2: split it before padding
        spec[-1] *= 0.5
    out = np.zeros(factor * n // 2 + 1, dtype=complex)
    out[: spec.size] = spec
    return np.fft.irfft(out, factor * n) * factor


def _piece(alpha: float, c: float, ya: float, za: float):
    """``z(y) = za e^{-c (y - ya)} + alpha (1 - e^{-c (y - ya)})/c``: ``dz/dy = alpha - c z``."""

    def z_of(y: float) -> float:
        d = y - ya
        x = -c * d
        if abs(x) < 1e-5:
            phi1 = 1.0 + x * (0.5 + x * (1.0 / 6.0 + x / 24.0))
        elif x > 700.0:
            return math.inf
        else:
            phi1 = math.expm1(x) / x
        return za * math.exp(x) + alpha * d * phi1

    return z_of


def _branch(p: StructuralParams, sigma: float, ya: float, za: float):
    """The monotone stroke in direction ``sigma`` from ``(ya, za)`` at nu = 1.

    Returns ``(z_of, y_cross, after)``: z as a smooth function of y up to where z
    crosses zero (``y_cross``, ``+-inf`` when it moves away from zero), and the
    function after the crossing (None without one). The two join with equal value
    and slope (alpha); the second derivative jumps, so the integrator splits its
    step at ``y_cross``.
    """
    alpha, b1, b2 = p.alpha, p.beta * p.gamma, p.beta * p.delta
    s0 = math.copysign(1.0, za) if za != 0.0 else sigma
    c0 = b1 * sigma + b2 * s0
    first = _piece(alpha, c0, ya, za)
    if s0 != sigma and 1.0 - c0 * za / alpha > 0.0:
        yc = ya + (math.log1p(-c0 * za / alpha) / c0 if c0 != 0.0 else -za / alpha)
        return first, yc, _piece(alpha, b1 * sigma + b2 * sigma, yc, 0.0)
    return first, math.inf * sigma, None


def _lagrange(grid: list[float], spacing: float, t: float) -> float:
    """The input at an off-grid time ``t``: 8-point Lagrange interpolant of the fine grid."""
    j = int(math.floor(t / spacing))
    j0 = min(max(j - _LAGRANGE // 2 + 1, 0), len(grid) - _LAGRANGE)
    x = t / spacing
    total = 0.0
    for i in range(j0, j0 + _LAGRANGE):
        w = 1.0
        for m in range(j0, j0 + _LAGRANGE):
            if m != i:
                w *= (x - m) / (i - m)
        total += w * grid[i]
    return total


def _rk4_nu1(
    p: StructuralParams, fine: list[float], h: float, steps_per_sample: int, total: int, x0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nu = 1 fast path: RK4 on ``m y'' = u - c y' - k y - Z(y)`` (module docstring).

    ``fine`` holds the input at ``t = j h / 2``; returns y, y', z at every
    ``steps_per_sample``-th step of ``total``, the last step included. A step in
    which the velocity reverses or z crosses zero is split at the event (located on
    the step's cubic Hermite interpolant), so every sub-step sees a smooth right-hand side.
    """
    m, c, k = p.m, p.c, p.k
    inv_m = 1.0 / m
    y, v, z = (float(a) for a in x0)
    a0 = (fine[0] - c * v - k * y - z) * inv_m
    sigma = math.copysign(1.0, v) if v != 0.0 else (math.copysign(1.0, a0) if a0 else 1.0)
    zf, yc, after = _branch(p, sigma, y, z)
    n = total // steps_per_sample + 1
    ys, vs, zs = np.empty(n), np.empty(n), np.empty(n)
    half = 0.5 * h

    def step(y, v, hh, u0, um, u1):
        a1 = (u0 - c * v - k * y - zf(y)) * inv_m
        y2, v2 = y + 0.5 * hh * v, v + 0.5 * hh * a1
        a2 = (um - c * v2 - k * y2 - zf(y2)) * inv_m
        y3, v3 = y + 0.5 * hh * v2, v + 0.5 * hh * a2
        a3 = (um - c * v3 - k * y3 - zf(y3)) * inv_m
        y4, v4 = y + hh * v3, v + hh * a3
        a4 = (u1 - c * v4 - k * y4 - zf(y4)) * inv_m
        yn = y + hh / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
        vn = v + hh / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        return yn, vn, a1  # the acceleration at the end only where an event needs it

    def u_at(t: float) -> float:
        on_grid = t / half
        if abs(on_grid - round(on_grid)) < 1e-9:
            return fine[round(on_grid)]
        return _lagrange(fine, half, t)

    for j in range(total):
        if j % steps_per_sample == 0:
            i = j // steps_per_sample
            ys[i], vs[i], zs[i] = y, v, zf(y)
        t, t_end = j * h, (j + 1) * h
        ua = fine[2 * j]
        for _ in range(8):  # sub-steps: at most a few events per step
            hh = t_end - t
            um = fine[2 * j + 1] if t == j * h else u_at(t + 0.5 * hh)
            u1 = fine[2 * j + 2]
            yn, vn, a_s = step(y, v, hh, ua, um, u1)
            rev = vn * sigma < 0.0
            cross = after is not None and sigma * (yn - yc) > 0.0
            if not (rev or cross):
                y, v = yn, vn
                break
            if rev:
                a_e = (u1 - c * vn - k * yn - zf(yn)) * inv_m
                th_rev = _hermite_root(v, a_s * hh, vn, a_e * hh)
            else:
                th_rev = 2.0
            th_cr = _hermite_root(y - yc, v * hh, yn - yc, vn * hh) if cross else 2.0
            th = min(th_rev, th_cr) * hh
            ue = u_at(t + th)
            y, v, _ = step(y, v, th, ua, u_at(t + 0.5 * th), ue)
            t, ua = t + th, ue
            if th_rev < th_cr:
                sigma = -sigma
                zf, yc, after = _branch(p, sigma, y, zf(y))
            else:
                zf, yc, after = after, math.inf * sigma, None
        else:
            raise _too_many_events(t)
        if not (math.isfinite(y) and math.isfinite(v)):
            raise _diverged(j * h)
    ys[-1], vs[-1], zs[-1] = y, v, zf(y)
    return ys, vs, zs


def _too_many_events(t: float) -> SolverError:
    return SolverError(
        f"more than 8 events within one integration step at t = {t:.6g} s; raise the "
        "upsampling factor"
    )


def _diverged(t: float) -> SolverError:
    return SolverError(f"the structural simulation diverged at t = {t:.6g} s")


def rk4_compiled(
    p: StructuralParams, fine: np.ndarray, h: float, steps_per_sample: int, total: int, x0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_rk4_nu1` compiled (:mod:`.structural_compiled`): the same floats to the bit
    (tested), about 20 times faster; its errors raised here, with the same messages."""
    from .structural_compiled import rk4_nu1  # here: numba is loaded by a simulation only

    pars = (p.m, p.c, p.k, p.alpha, p.beta, p.gamma, p.delta)
    code, step, t, ys, vs, zs = rk4_nu1(pars, fine, h, steps_per_sample, total, x0)
    if code == 1:
        raise _too_many_events(t)
    if code == 2:
        raise _diverged(step * h)
    return ys, vs, zs


def _hermite_root(v0: float, d0: float, v1: float, d1: float) -> float:
    """The zero in (0, 1) of the cubic Hermite interpolant with ends v0, v1 and slopes d0, d1."""

    def val(s: float) -> float:
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        return h00 * v0 + h10 * d0 + h01 * v1 + h11 * d1

    lo, hi = 0.0, 1.0
    flo = val(lo)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        s2, s3 = mid**2, mid**3  # val(mid) inlined (the same operations, without the call)
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


def _dop853(
    p: StructuralParams, fine: np.ndarray, h: float, dt: float, total: int, x0, rtol: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Any nu: the (y, y', z) ODE with scipy's DOP853 and its dense output at the samples."""
    from scipy.integrate import solve_ivp

    grid = fine.tolist()
    half = 0.5 * h
    b1, b2, nu = p.beta * p.gamma, p.beta * p.delta, p.nu

    def rhs(t, x):
        y, v, z = x
        u = _lagrange(grid, half, t)
        az = abs(z)
        zn1 = az ** (nu - 1.0) if nu != 1.0 else 1.0
        return [
            v,
            (u - p.c * v - p.k * y - z) / p.m,
            p.alpha * v - b1 * abs(v) * zn1 * z - b2 * v * zn1 * az,
        ]

    scale = max(float(np.max(np.abs(fine))), 1e-300)
    atol = rtol * np.array(
        [scale / (p.k + p.alpha), scale / math.sqrt(p.m * (p.k + p.alpha)), scale]
    )
    n = total + 1
    t_eval = np.arange(n) * dt
    sol = solve_ivp(
        rhs,
        (0.0, total * dt),
        np.asarray(x0, float),
        method="DOP853",
        t_eval=t_eval,
        rtol=rtol,
        atol=atol,
    )
    if not sol.success:
        raise SolverError(f"DOP853 failed on the structural form: {sol.message}")
    return sol.y[0], sol.y[1], sol.y[2]


def _check(params: StructuralParams, u: np.ndarray, dt: float, upsample: int) -> np.ndarray:
    if not isinstance(params, StructuralParams):
        raise InputError(f"expected StructuralParams, got {type(params).__name__}")
    real(dt, "dt (s)", within=DT)
    integer(upsample, "upsample", within=UPSAMPLE)
    u = np.asarray(u, dtype=float)
    if u.ndim != 1 or u.size < 2 or not np.all(np.isfinite(u)):
        raise InputError("the input must be a finite 1-D array of at least 2 samples")
    return u


def simulate_structural(
    params: StructuralParams,
    u: np.ndarray,
    dt: float,
    *,
    periodic: bool = False,
    x0: Sequence[float] = (0.0, 0.0, 0.0),
    upsample: int = 8,
    rtol: float | None = None,
    method: str = "rk4",
    allow_unbounded: bool = False,
) -> StructuralRun:
    """Simulate the structural form from ``x0 = (y, y', z)`` at ``t_0`` on samples ``u``.

    Parameters
    ----------
    params : StructuralParams
    u : array_like, shape (N,)
        Input samples at ``t_k = k dt`` (input unit); ``periodic``: one period.
    dt : float
        Sample time (s).
    periodic : bool
        Interpolate ``u`` as one period of a periodic input (else reflected at the ends).
    x0 : 3 floats
        ``(y, y', z)`` at ``t_0``.
    upsample : int
        Integration steps per sample (the start value under ``rtol``).
    rtol : float or None
        Error control (module docstring): for ``"rk4"`` the relative bound on the
        step-doubling estimate; for ``"dop853"`` the solver's tolerance (default 1e-10).
    method : {"rk4", "dop853"}
        ``"rk4"``, the nu = 1 fast path, needs ``nu = 1``.
    allow_unbounded : bool
        Accept parameters with which z escapes in a finite stroke.

    Raises
    ------
    InputError, UnboundedModelError, SolverError
    """
    u = _check(params, u, dt, upsample)
    require_bounded_structural(params, allow_unbounded)
    if method not in ("rk4", "dop853"):
        raise InputError(f'method must be "rk4" or "dop853", got {method!r}')
    if method == "rk4" and params.nu != 1.0:
        raise InputError(f'method "rk4" is the nu = 1 fast path; nu = {params.nu:g} needs "dop853"')
    n = u.size
    if method == "dop853":
        fine = _fine(u, upsample, periodic)
        samples = _steps(u, 1, periodic)
        tol = 1e-10 if rtol is None else rtol
        y, v, z = _dop853(params, fine, dt / upsample, dt, samples, x0, tol)
        state = np.array([y[-1], v[-1], z[-1]])
        return StructuralRun(y[:n], v[:n], z[:n], state, upsample=upsample)
    run = _rk4_run(params, u, dt, upsample, periodic, x0)
    if rtol is None:
        return run
    real(rtol, "rtol", within=Range(1e-15, 1.0))
    r = upsample
    while True:
        finer = _rk4_run(params, u, dt, 2 * r, periodic, x0)
        est = float(np.max(np.abs(finer.y - run.y))) / 15.0
        scale = float(np.max(np.abs(finer.y)))
        if est <= rtol * scale or 2 * r >= UPSAMPLE.hi:
            return StructuralRun(
                finer.y, finer.v, finer.z, finer.state, upsample=2 * r, error_estimate=est
            )
        run, r = finer, 2 * r


def _fine(u: np.ndarray, upsample: int, periodic: bool) -> np.ndarray:
    """The input at half steps ``j dt / (2 upsample)``: over one period and a few points
    past it (periodic), or from ``t_0`` to ``t_{N-1}`` (non-periodic)."""
    g = band_limited(u, 2 * upsample, periodic=periodic)
    return np.concatenate([g, g[: 2 * _LAGRANGE]]) if periodic else g


def _steps(u: np.ndarray, upsample: int, periodic: bool) -> int:
    """Integration steps: to the end of the period, or to the record's last sample."""
    return upsample * (u.size if periodic else u.size - 1)


def _rk4_run(
    params: StructuralParams, u: np.ndarray, dt: float, upsample: int, periodic: bool, x0
) -> StructuralRun:
    fine = _fine(u, upsample, periodic)
    total = _steps(u, upsample, periodic)
    y, v, z = rk4_compiled(params, fine, dt / upsample, upsample, total, x0)
    n = u.size
    state = np.array([y[-1], v[-1], z[-1]])
    return StructuralRun(y[:n], v[:n], z[:n], state, upsample=upsample)


def steady_state(
    params: StructuralParams,
    u: np.ndarray,
    dt: float,
    *,
    tol: float = 1e-10,
    max_periods: int = 50,
    **options,
) -> StructuralRun:
    """The periodic steady state for one period ``u`` of a periodic input.

    Simulates period after period from rest (or ``x0``, e.g. the state of a nearby
    steady state) until the state at the end of a period is within ``tol`` (relative
    to the period's largest |y|, |y'|, |z|) of the state at its start, and returns
    that last period. ``options`` go to
    :func:`simulate_structural` (``periodic`` is implied).

    Raises
    ------
    SolverError
        No steady state within ``max_periods`` periods.
    """
    options["periodic"] = True
    x = np.asarray(options.pop("x0", (0.0, 0.0, 0.0)), dtype=float)
    for period in range(1, max_periods + 1):
        run = simulate_structural(params, u, dt, x0=x, **options)
        scale = np.array([np.max(np.abs(a)) for a in (run.y, run.v, run.z)])
        start = np.array([run.y[0], run.v[0], run.z[0]])
        if np.all(np.abs(run.state - start) <= tol * np.maximum(scale, 1e-300)):
            return StructuralRun(
                run.y, run.v, run.z, run.state, run.upsample, run.error_estimate, periods=period
            )
        x = run.state
    raise SolverError(
        f"no periodic steady state within {max_periods} periods (tolerance {tol:g}); the "
        "response may not be periodic (a subharmonic or drifting response)"
    )


def simulate_batch(
    params: Sequence[StructuralParams],
    u: np.ndarray,
    dt: float,
    *,
    periodic: bool = False,
    steady: bool = False,
    **options,
) -> np.ndarray:
    """Displacements of several scenarios: ``params[b]`` on ``u[b]`` (or one shared ``u``).

    Returns an array of shape ``(B, N)``; ``steady`` runs :func:`steady_state` (one
    period each), else :func:`simulate_structural`.
    """
    u = np.asarray(u, dtype=float)
    rows = np.broadcast_to(u, (len(params), u.shape[-1])) if u.ndim == 1 else u
    if rows.shape[0] != len(params):
        raise InputError(f"{len(params)} parameter sets for {rows.shape[0]} input rows")
    out = np.empty(rows.shape)
    for b, (p, row) in enumerate(zip(params, rows, strict=True)):
        if steady:
            out[b] = steady_state(p, row, dt, **options).y
        else:
            out[b] = simulate_structural(p, row, dt, periodic=periodic, **options).y
    return out
