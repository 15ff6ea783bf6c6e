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
from ..errors import InputError, ParameterError, SolverError
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
#: Equation-error starts refined by output error, at most (best first).
MAX_STARTS = 3
#: Training fit (%) at which no further start is refined.
GOOD_FIT = 90.0


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
def _derivatives(x: np.ndarray, dt: float, periodic: bool, f_top: float) -> np.ndarray:
    """x and its first three derivatives by FFT (the record reflected when not periodic):
    every line up to the excited band's top ``f_top`` (Hz) is kept, above it only the
    lines that stand out of the noise floor (4 times the median amplitude of the top
    fifth of the band), so the harmonics the hysteresis makes are kept and the noise
    between them is not."""
    x = np.asarray(x, dtype=float)
    ext = x if periodic else np.concatenate([x, x[-2:0:-1]])
    n = ext.size
    f = np.fft.rfftfreq(n, dt)
    spec = np.fft.rfft(ext - ext.mean())
    floor = float(np.median(np.abs(spec[f >= 0.8 * f[-1]])))
    spec[(f > f_top) & (np.abs(spec) <= 4.0 * floor)] = 0.0
    w = 2j * np.pi * f
    out = [np.fft.irfft(spec * w**p, n)[: x.size] for p in range(4)]
    out[0] = out[0] + ext.mean()
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

    Linear least squares on ``G (K - m w^2 + i c w) = 1``, reweighted by the previous
    fit's ``1/|K - m w^2 + i c w|`` (Sanathanan-Koerner, 5 passes), so each line counts
    by its error in G, not in 1/G (where the weak high-frequency lines would dominate).

    Raises
    ------
    InputError
        The records excite too few lines, or the fit has no positive mass and stiffness.
    """
    lines = [_frf(data, periodic) for data in records]
    if sum(w.size for w, _ in lines) < 3:
        raise InputError("the records excite too few frequency lines to fit the linear part")
    theta = None
    for _ in range(5):
        rows, rhs = [], []
        for w, g in lines:
            a = np.stack([g, -(w**2) * g, 1j * w * g], axis=1)
            wt = (
                1.0
                if theta is None
                else 1.0 / np.abs(theta[0] - theta[1] * w**2 + 1j * theta[2] * w)
            )
            a = a * np.reshape(wt, (-1, 1))
            rows += [a.real, a.imag]
            rhs += [np.ones(w.size) * wt, np.zeros(w.size)]
        theta = np.linalg.lstsq(np.concatenate(rows), np.concatenate(rhs), rcond=None)[0]
    k_tot, m, c = theta
    if not (m > 0 and k_tot > 0):
        raise InputError(
            f"the frequency response gives no mass-spring system (m = {m:.3g}, k + alpha = "
            f"{k_tot:.3g}): is this a structural Bouc-Wen record (force in, displacement out)?"
        )
    return {"m": float(m), "c_eq": float(max(c, 0.0)), "K": float(k_tot)}


# -- equation error --------------------------------------------------------------------------------
def _lowpass(r: np.ndarray, dt: float, f_top: float) -> np.ndarray:
    """The lines of ``r`` up to ``f_top`` (Hz), as real and imaginary parts."""
    spec = np.fft.rfft(r)[np.fft.rfftfreq(r.size, dt) <= f_top]
    return np.concatenate([spec.real, spec.imag]) / math.sqrt(r.size)


def equation_error_start(
    records: Sequence[IdentificationData], periodic: bool, lin: dict[str, float]
) -> list[np.ndarray]:
    """Candidate ``(m, c, k, alpha, beta_gamma, beta_delta)``, best first, from the z equation.

    With band-limited derivatives of y and u, ``z = u - m y2 - c y1 - k y`` and its
    derivative ``dz = du - m y3 - c y2 - k y1`` (``yp``: the p-th derivative of y) must
    satisfy ``dz = alpha y1 - beta_gamma |y1| z - beta_delta y1 |z|`` at every sample;
    the residual's lines in the excited band (where the noise is smallest against the
    signal) are fitted from several splits of ``K`` between k and alpha and several
    hysteresis shapes.
    """
    from scipy.optimize import least_squares

    sigs = []
    for data in records:
        f_top = _top_frequency(data)
        y = _derivatives(data.y, data.dt, periodic, f_top)
        du = _derivatives(data.u, data.dt, periodic, 0.5 / data.dt)[1]
        sigs.append((np.asarray(data.u), du, y, data.dt, f_top))
    ys = np.concatenate([s[2][0] - s[2][0].mean() for s in sigs])
    scale_y = max(float(np.sqrt(np.mean(ys**2))), 1e-300)
    scale_v = max(float(np.sqrt(np.mean(np.concatenate([s[2][1] for s in sigs]) ** 2))), 1e-300)

    def resid(q: np.ndarray) -> np.ndarray:
        m, c, k, alpha = np.exp(q[:4])
        b1, b2 = q[4] / scale_y, q[5] / scale_y
        out = []
        for u, du, (y, y1, y2, y3), dt, f_top in sigs:
            z = u - m * y2 - c * y1 - k * y
            dz = du - m * y3 - c * y2 - k * y1
            r = dz - alpha * y1 + b1 * np.abs(y1) * z + b2 * y1 * np.abs(z)
            out.append(_lowpass(r, dt, f_top) / (lin["K"] * scale_v))
        return np.concatenate(out)

    found = []
    for frac in (0.25, 0.5, 0.75):
        for s1, s2 in ((0.0, 0.0), (0.5, -0.5), (0.5, 0.5), (3.0, -3.0), (3.0, 3.0), (3.0, 0.0)):
            q0 = np.array(
                [
                    math.log(lin["m"]),
                    math.log(max(lin["c_eq"], 1e-9 * lin["K"])),
                    math.log((1 - frac) * lin["K"]),
                    math.log(frac * lin["K"]),
                    s1,
                    s2,
                ]
            )
            sol = least_squares(resid, q0, method="trf", max_nfev=200)
            found.append((sol.cost, np.concatenate([np.exp(sol.x[:4]), sol.x[4:] / scale_y])))
    found.sort(key=lambda t: t[0])
    out: list[np.ndarray] = []
    for _, cand in found:  # distinct candidates only
        if all(np.max(np.abs(cand - o) / (np.abs(o) + 1e-12)) > 1e-3 for o in out):
            out.append(cand)
    return out


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
        self.failed = False

    def __call__(self, q: np.ndarray) -> np.ndarray:
        out = []
        self.failed = True
        try:
            p = _params(q, self.scale_y, self.name, self.units)
            for i, data in enumerate(self.records):
                out.append(self.simulate(i, p, data) - self.ys[i])
        except (SolverError, InputError, ParameterError, FloatingPointError, OverflowError):
            return np.full(sum(y.size for y in self.ys), 1e3 * self.scale_y)
        r = np.concatenate(out)
        if not np.all(np.isfinite(r)):
            return np.full(r.size, 1e3 * self.scale_y)
        self.failed = False
        return r

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
    SolverError
        The model simulates from no start.
    """
    from scipy.optimize import least_squares

    say = progress or (lambda _msg: None)
    if not records:
        raise InputError("identify_structural needs at least one record")
    start = time.perf_counter()
    lin = linear_start(records, periodic)
    say(f"linear part: m {lin['m']:.4g}, c_eq {lin['c_eq']:.4g}, k + alpha {lin['K']:.4g}")
    # the equation-error candidates, then the linear fit with a mild hysteresis (k = alpha
    # = K/2, beta_gamma y_rms = 0.5: class I, it always simulates) when none does or fits
    scale_y = float(np.sqrt(np.mean(np.concatenate([d.y - np.mean(d.y) for d in records]) ** 2)))
    c_eq, half = max(lin["c_eq"], 1e-9 * lin["K"]), lin["K"] / 2
    eq_starts = equation_error_start(records, periodic, lin)[:MAX_STARTS]
    cands = [(f"equation-error start {i + 1}", c) for i, c in enumerate(eq_starts)]
    cands.append(("linear start", np.array([lin["m"], c_eq, half, half, 0.5 / scale_y, 0.0])))
    fun = _OutputError(list(records), periodic, scale_y, name, units)
    ys = np.concatenate(fun.ys)
    best = None
    for label, eq in cands:
        shown = ", ".join(f"{n} {v:.4g}" for n, v in zip(DETERMINED, eq, strict=True))
        q0 = np.concatenate([np.log(eq[:4]), eq[4:] * scale_y])
        fun(q0)
        if fun.failed:
            say(f"{label} ({shown}) does not simulate: next")
            continue
        say(f"{label}: {shown}")
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
        if best is None or float(r @ r) < float(best[1] @ best[1]):
            best = (sol, r, eq, not fun.failed)
        if not fun.failed and fit_percent(ys, ys + r) >= GOOD_FIT:
            break
    if best is None:
        raise SolverError(
            "no start of the structural fit simulates on this record (z grows without bound "
            "from every start): is it a structural Bouc-Wen record?"
        )
    sol, r, eq, simulated = best
    return _result(sol, r, fun, lin, eq, validation, start, simulated)


def _result(sol, r, fun, lin, eq, validation, start, simulated) -> StructuralFit:
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
    converged = bool(sol.status > 0 and simulated)
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
