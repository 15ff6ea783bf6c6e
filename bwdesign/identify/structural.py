"""Output-error identification of the structural Bouc-Wen form (nu = 1), no initial guess needed.

The coordinates are the ones the data determine. In the structural form beta only
ever multiplies gamma and delta (``z' = alpha y' - (beta gamma) |y'| z - (beta delta)
y' |z|`` at nu = 1), so a record determines ``m, c, k, alpha``, ``beta_gamma = beta
gamma`` and ``beta_delta = beta delta`` and nothing about beta, gamma and delta
apart: the fit reports intervals for those six and writes the stage file with
``beta = 1`` (a convention, said so in the file), ``gamma = beta_gamma`` and
``delta = beta_delta``.

Three stages, each started from the one before:

1. **Linear part** (:func:`linear_start`): the frequency response on the excited
   lines (periodic records: DFT ratio; other records: Welch H1), fitted by linear
   least squares as ``1/G = K - m w^2 + i c_eq w``: the mass, an equivalent damping
   and the total stiffness ``K = k + alpha`` the amplitude sees.
2. **Equation error** (:func:`equation_error_start`): with band-limited derivatives
   of y, the restoring force ``z = u - m y'' - c y' - k y`` must satisfy the
   integrated z equation ``z - alpha y + integral(beta_gamma |y'| z + beta_delta y'
   |z|) = const``; a small nonlinear least-squares problem (no simulation), from a
   few splits of K between k and alpha.
3. **Output error**: the simulated output (:mod:`bwdesign.model.structural_sim`, in
   the periodic steady state for periodic records) against the measured one,
   Levenberg-Marquardt-type trust region in log coordinates for m, c, k, alpha and
   output-scaled ones for the products; intervals from the Newey-West sandwich
   covariance of :mod:`bwdesign.identify.result`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._version import __version__
from ..errors import InputError, SolverError
from ..model.structural import StructuralParams
from ..model.structural_sim import simulate_structural, steady_state
from .data import IdentificationData
from .result import Z95, fit_percent, sandwich_covariance
from .score import score_record

__all__ = [
    "StructuralFit",
    "identify_structural",
    "linear_start",
    "equation_error_start",
    "structural_stage_toml",
    "DETERMINED",
]

#: The coordinates a record determines (module docstring).
DETERMINED = ("m", "c", "k", "alpha", "beta_gamma", "beta_delta")
#: Integration steps per sample inside the fit (error ~1e-8 of the output on the benchmark).
FIT_UPSAMPLE = 4


@dataclass(frozen=True, kw_only=True, eq=False)
class StructuralFit:
    """Outcome of :func:`identify_structural` (units: the records' and the form's).

    Attributes
    ----------
    params : StructuralParams
        The fit with ``beta = 1`` (convention), ``gamma = beta_gamma``, ``delta = beta_delta``.
    values, std_err : dict
        Per determined coordinate (:data:`DETERMINED`).
    ci95 : dict
        95 % interval ``(low, high)`` per determined coordinate.
    fit_percent : dict
        ``train`` and ``validation`` (None without validation records).
    residual_rms, residual_rms_validation : float, float or None
        RMS output error (length unit) on the training and the validation records.
    validation : list of dict
        Per validation record: source, fit_percent, rms_error.
    converged : bool
    reason : str
    seconds : float
        Wall time of the identification.
    starts : dict
        The linear and the equation-error start values.
    traces : dict
        ``t, u, y, y_model`` of the first training record and ``val_t, val_y,
        val_y_model`` of the first validation record (the report's figures).
    dt : float
        Sample time of the first training record (s).
    """

    params: StructuralParams
    values: dict[str, float]
    std_err: dict[str, float]
    ci95: dict[str, tuple[float, float]]
    fit_percent: dict[str, float | None]
    residual_rms: float
    residual_rms_validation: float | None
    validation: list[dict[str, Any]]
    converged: bool
    reason: str
    seconds: float
    periodic: bool
    starts: dict[str, Any] = field(default_factory=dict)
    traces: dict[str, np.ndarray] = field(default_factory=dict)
    dt: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "form": "structural",
            "plant": self.params.to_dict(),
            "determined": {
                k: {"value": self.values[k], "std_err": self.std_err[k], "ci95": self.ci95[k]}
                for k in DETERMINED
            },
            "not_determined": {
                "parameters": ["beta", "gamma", "delta"],
                "why": "beta multiplies gamma and delta everywhere in the model: only the "
                "products beta*gamma and beta*delta are determined; the stage file's beta = 1 "
                "is a convention, not a measurement",
            },
            "fit_percent": self.fit_percent,
            "residual_rms": self.residual_rms,
            "residual_rms_validation": self.residual_rms_validation,
            "validation": self.validation,
            "periodic": self.periodic,
            "converged": self.converged,
            "reason": self.reason,
            "seconds": self.seconds,
            "starts": self.starts,
        }


# -- derivatives and the linear start ------------------------------------------------------------
def _derivatives(data: IdentificationData, periodic: bool, f_cut: float) -> np.ndarray:
    """y, y', y'' band-limited below ``f_cut`` (Hz), by FFT (reflected when not periodic)."""
    y = np.asarray(data.y, dtype=float)
    x = y if periodic else np.concatenate([y, y[-2:0:-1]])
    n = x.size
    f = np.fft.rfftfreq(n, data.dt)
    spec = np.fft.rfft(x - x.mean())
    spec[f > f_cut] = 0.0
    w = 2j * np.pi * f
    out = [np.fft.irfft(spec * w**p, n)[: y.size] for p in (0, 1, 2)]
    out[0] = out[0] + x.mean()
    return np.array(out)


def _frf(data: IdentificationData, periodic: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(w, G)`` on the excited lines (rad/s)."""
    u, y = np.asarray(data.u), np.asarray(data.y)
    if periodic:
        uf, yf = np.fft.rfft(u - u.mean()), np.fft.rfft(y - y.mean())
        f = np.fft.rfftfreq(u.size, data.dt)
        keep = np.abs(uf) > 1e-2 * np.max(np.abs(uf))
        keep[0] = False
        return 2 * np.pi * f[keep], yf[keep] / uf[keep]
    from scipy.signal import csd, welch

    nper = int(min(u.size, 1024))
    f, puu = welch(u, fs=1 / data.dt, nperseg=nper)
    _, puy = csd(u, y, fs=1 / data.dt, nperseg=nper)
    keep = puu > 1e-3 * puu.max()
    keep[0] = False
    return 2 * np.pi * f[keep], puy[keep] / puu[keep]


def linear_start(records: Sequence[IdentificationData], periodic: bool) -> dict[str, float]:
    """``m``, ``c_eq`` and ``K = k + alpha`` from the frequency response (module docstring).

    Raises
    ------
    InputError
        The records excite too few lines, or the fit has no positive mass and stiffness.
    """
    rows, rhs = [], []
    for data in records:
        w, g = _frf(data, periodic)
        a = np.stack([g, -(w**2) * g, 1j * w * g], axis=1)
        rows += [a.real, a.imag]
        rhs += [np.ones(w.size), np.zeros(w.size)]
    a, b = np.concatenate(rows), np.concatenate(rhs)
    if a.shape[0] < 6:
        raise InputError("the records excite too few frequency lines to fit the linear part")
    k_tot, m, c = np.linalg.lstsq(a, b, rcond=None)[0]
    if not (m > 0 and k_tot > 0):
        raise InputError(
            f"the frequency response gives no mass-spring system (m = {m:.3g}, k + alpha = "
            f"{k_tot:.3g}): is this a structural Bouc-Wen record (force in, displacement out)?"
        )
    return {"m": float(m), "c_eq": float(max(c, 0.0)), "K": float(k_tot)}


# -- equation error --------------------------------------------------------------------------------
def _integral(x: np.ndarray, dt: float, periodic: bool) -> np.ndarray:
    if periodic:
        spec = np.fft.rfft(x)
        f = np.fft.rfftfreq(x.size, dt)
        spec[0] = 0.0
        spec[1:] /= 2j * np.pi * f[1:]
        return np.fft.irfft(spec, x.size)
    from scipy.integrate import cumulative_trapezoid

    return cumulative_trapezoid(x, dx=dt, initial=0.0)


def equation_error_start(
    records: Sequence[IdentificationData], periodic: bool, lin: dict[str, float]
) -> np.ndarray:
    """``(m, c, k, alpha, beta_gamma, beta_delta)`` from the integrated z equation."""
    from scipy.optimize import least_squares

    sigs = []
    for data in records:
        f_top = _top_frequency(data)
        y, yd, ydd = _derivatives(data, periodic, min(0.5 / data.dt, 1.5 * f_top))
        sigs.append((np.asarray(data.u), y, yd, ydd, data.dt))
    scale_y = max(
        float(np.sqrt(np.mean(np.concatenate([s[1] - s[1].mean() for s in sigs]) ** 2))), 1e-300
    )

    def resid(q: np.ndarray) -> np.ndarray:
        m, c, k, alpha = np.exp(q[:4])
        b1, b2 = q[4] / scale_y, q[5] / scale_y
        out = []
        for u, y, yd, ydd, dt in sigs:
            z = u - m * ydd - c * yd - k * y
            e = z - alpha * y + _integral(b1 * np.abs(yd) * z + b2 * yd * np.abs(z), dt, periodic)
            out.append((e - e.mean()) / lin["K"] / scale_y)
        return np.concatenate(out)

    best = None
    for frac in (0.25, 0.5, 0.75):
        for s1, s2 in ((0.0, 0.0), (0.5, -0.5), (0.5, 0.5)):
            q0 = np.array(
                [
                    math.log(lin["m"]),
                    math.log(max(lin["c_eq"], 1e-6 * lin["K"] * 1e-3)),
                    math.log((1 - frac) * lin["K"]),
                    math.log(frac * lin["K"]),
                    s1,
                    s2,
                ]
            )
            sol = least_squares(resid, q0, method="trf", max_nfev=200)
            if best is None or sol.cost < best.cost:
                best = sol
    q = best.x
    return np.concatenate([np.exp(q[:4]), q[4:] / scale_y])


def _top_frequency(data: IdentificationData) -> float:
    """The highest frequency (Hz) with 1e-3 of the input's peak spectral amplitude."""
    uf = np.abs(np.fft.rfft(np.asarray(data.u) - np.mean(data.u)))
    f = np.fft.rfftfreq(data.n, data.dt)
    return float(f[np.flatnonzero(uf > 1e-3 * uf.max())[-1]])


# -- output error ----------------------------------------------------------------------------------
def _params(q: np.ndarray, scale_y: float, name: str, units: tuple[str, str]) -> StructuralParams:
    m, c, k, alpha = np.exp(q[:4])
    return StructuralParams(
        m=m,
        c=c,
        k=k,
        alpha=alpha,
        beta=1.0,
        gamma=q[4] / scale_y,
        delta=q[5] / scale_y,
        nu=1.0,
        name=name,
        length_unit=units[0],
        input_unit=units[1],
    )


class _OutputError:
    """The output-error residual over the training records, warm-starting steady states."""

    def __init__(self, records, periodic, scale_y, name, units):
        self.records, self.periodic, self.scale_y = records, periodic, scale_y
        self.name, self.units = name, units
        self.x0 = [None] * len(records)
        self.ys = [np.asarray(d.y) for d in records]

    def __call__(self, q: np.ndarray) -> np.ndarray:
        out = []
        try:
            p = _params(q, self.scale_y, self.name, self.units)
            for i, data in enumerate(self.records):
                out.append(self.simulate(i, p, data) - self.ys[i])
        except (SolverError, InputError, FloatingPointError, OverflowError):
            return np.full(sum(y.size for y in self.ys), 1e3 * self.scale_y)
        r = np.concatenate(out)
        return r if np.all(np.isfinite(r)) else np.full(r.size, 1e3 * self.scale_y)

    def simulate(self, i: int, p: StructuralParams, data: IdentificationData) -> np.ndarray:
        opts = {"upsample": FIT_UPSAMPLE, "allow_unbounded": True}
        if not self.periodic:
            return simulate_structural(p, data.u, data.dt, **opts).y
        x0 = self.x0[i] if self.x0[i] is not None else (0.0, 0.0, 0.0)
        run = steady_state(p, data.u, data.dt, x0=x0, tol=1e-10, **opts)
        self.x0[i] = (run.y[0], run.v[0], run.z[0])
        return run.y


def identify_structural(
    records: Sequence[IdentificationData],
    *,
    periodic: bool = False,
    validation: Sequence[IdentificationData] | None = None,
    name: str = "",
    units: tuple[str, str] = ("m", "N"),
    max_nfev: int = 60,
    progress: Callable[[str], None] | None = None,
) -> StructuralFit:
    """Fit the structural form (nu = 1) to ``records`` (module docstring).

    ``periodic``: every record is one period of a periodic input, fitted and scored in
    the periodic steady state; otherwise each starts at rest. ``units``: the records'
    (length, input) units, written to the stage file.

    Raises
    ------
    InputError
        No records, or records without a mass-spring frequency response.
    """
    from scipy.optimize import least_squares

    say = progress or (lambda _msg: None)
    if not records:
        raise InputError("identify_structural needs at least one record")
    start = time.perf_counter()
    lin = linear_start(records, periodic)
    say(f"linear part: m {lin['m']:.4g}, c_eq {lin['c_eq']:.4g}, k + alpha {lin['K']:.4g}")
    eq = equation_error_start(records, periodic, lin)
    say(
        "equation-error start: "
        + ", ".join(f"{n} {v:.4g}" for n, v in zip(DETERMINED, eq, strict=True))
    )
    scale_y = float(np.sqrt(np.mean(np.concatenate([d.y - np.mean(d.y) for d in records]) ** 2)))
    fun = _OutputError(list(records), periodic, scale_y, name, units)
    q0 = np.concatenate([np.log(eq[:4]), eq[4:] * scale_y])
    sol = least_squares(
        fun,
        q0,
        method="trf",
        diff_step=1e-6,
        x_scale="jac",
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-12,
        max_nfev=max_nfev,
    )
    r = fun(sol.x)
    say(f"output error: {sol.nfev} evaluations, residual RMS {np.sqrt(np.mean(r**2)):.3g}")
    return _result(sol, r, fun, lin, eq, validation, start)


def _result(sol, r, fun, lin, eq, validation, start) -> StructuralFit:
    """The fit's values, intervals, scores and validation."""
    p = _params(sol.x, fun.scale_y, fun.name, fun.units)
    cov, _ = sandwich_covariance(sol.jac, r)
    se_q = np.sqrt(np.diag(cov))
    q = sol.x
    values = dict(
        zip(DETERMINED, [*np.exp(q[:4]), q[4] / fun.scale_y, q[5] / fun.scale_y], strict=True)
    )
    grad = [*np.exp(q[:4]), 1 / fun.scale_y, 1 / fun.scale_y]
    std = {n: float(g * s) for n, g, s in zip(DETERMINED, grad, se_q, strict=True)}
    ci = {}
    for n in DETERMINED:
        if n in ("m", "c", "k", "alpha"):  # symmetric in the log coordinate: positive limits
            i = DETERMINED.index(n)
            ci[n] = (float(np.exp(q[i] - Z95 * se_q[i])), float(np.exp(q[i] + Z95 * se_q[i])))
        else:
            ci[n] = (values[n] - Z95 * std[n], values[n] + Z95 * std[n])
    ys = np.concatenate(fun.ys)
    first = fun.records[0]
    traces = {"t": first.t, "u": first.u, "y": first.y, "y_model": fun.ys[0] + r[: first.n]}
    valid = []
    for data in validation or ():
        s = score_record(p, data, periodic=fun.periodic)
        valid.append(
            {"source": data.source, "fit_percent": s.fit_percent, "rms_error": s.rms_error}
        )
        if len(valid) == 1:
            traces.update(val_t=data.t, val_y=data.y, val_y_model=s.y_model)
    v_rms = float(np.sqrt(np.mean([v["rms_error"] ** 2 for v in valid]))) if valid else None
    converged = bool(sol.status > 0)
    return StructuralFit(
        params=p,
        values={k: float(v) for k, v in values.items()},
        std_err=std,
        ci95=ci,
        fit_percent={
            "train": fit_percent(ys, ys + r),
            "validation": float(np.mean([v["fit_percent"] for v in valid])) if valid else None,
        },
        residual_rms=float(np.sqrt(np.mean(r**2))),
        residual_rms_validation=v_rms,
        validation=valid,
        converged=converged,
        reason=str(sol.message),
        seconds=time.perf_counter() - start,
        periodic=fun.periodic,
        starts={
            "linear": lin,
            "equation_error": dict(zip(DETERMINED, map(float, eq), strict=True)),
        },
        traces=traces,
        dt=first.dt,
    )


def structural_stage_toml(fit: StructuralFit, records: Sequence[IdentificationData]) -> str:
    """The stage file of a structural fit: the intervals and the beta convention as comments."""
    lines = [
        f"# Identified by bwdesign {__version__} (structural Bouc-Wen form, nu = 1) from "
        + ", ".join(d.source or "a record" for d in records)
        + (" (periodic, in steady state)" if fit.periodic else " (from rest)"),
        f"# fit {fit.fit_percent['train']:.4f} %, residual RMS {fit.residual_rms:.4g} "
        f"{fit.params.length_unit}; 95 % intervals of what the data determine:",
    ]
    for n in DETERMINED:
        lo, hi = fit.ci95[n]
        lines.append(f"#   {n:<10} = {fit.values[n]:.10g}  [{lo:.8g}, {hi:.8g}]")
    lines += [
        "# beta, gamma and delta apart are NOT determined (beta multiplies gamma and delta",
        "# everywhere): beta = 1 below is a convention, gamma = beta*gamma, delta = beta*delta.",
        fit.params.to_toml().rstrip("\n"),
        "",
        "[sampling]",
        f"dt = {records[0].dt!r}",
    ]
    return "\n".join(lines) + "\n"
