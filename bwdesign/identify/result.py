"""The identification result: parameters, intervals, fit quality and plain-word diagnostics.

Intervals. The covariance of the fit coordinates is the sandwich
``B S B`` with ``B = (J^T J)^-1`` (from the SVD of the Jacobian ``J`` of the
scaled residuals at the optimum, central differences) and ``S`` the
Newey-West estimate of ``J^T Cov(r) J`` with Bartlett weights: it reduces to
the textbook ``s^2 (J^T J)^-1`` for white residuals and widens the intervals
when the residuals are correlated (unmodelled dynamics, coloured sensor
noise). Its lag is the first at which the residual autocorrelation drops
below ``2/sqrt(N)`` (at least the Newey-West rule ``4 (N/100)^(2/9)``, at most
``min(N/20, 400)``). Each variance is the larger of that estimate and the
white-noise one (Newey-West is biased low in finite samples). The six
parameters' covariance follows by the delta method; 95 % intervals are
``value ± 1.96 sd``. A parameter is *determined* when that half-width is
below 50 % of its value; otherwise its interval is reported (possibly
infinite) and a diagnostic says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model.params import BoucWenParams
from ..model.uncertainty import DisturbanceBound, UncertaintyBox
from .problem import (
    IA,
    IB,
    IE1,
    IE2,
    IK,
    IOFF,
    IQ,
    ITAU,
    IW,
    IZ,
    Q_MAX,
    Problem,
    params_from_theta,
)
from .stack import Stack

__all__ = [
    "IdentificationResult",
    "fit_percent",
    "pooled_fit",
    "residual_whiteness",
    "validate_record",
]

NAMES = ("a1", "a2", "a3", "alpha", "beta", "gamma")
Z95 = 1.959963984540054
_DETERMINED_REL = 0.5


def fit_percent(y: np.ndarray, y_model: np.ndarray) -> float:
    """``100 (1 - ||y - y_model|| / ||y - mean(y)||)`` (%)."""
    return float(100.0 * (1.0 - np.linalg.norm(y - y_model) / np.linalg.norm(y - np.mean(y))))


@dataclass(frozen=True, kw_only=True, eq=False)
class IdentificationResult:
    """Outcome of :func:`bwdesign.identify`.

    Attributes
    ----------
    params : BoucWenParams
        The identified stage (always in the bounded class).
    std_err : dict
        Standard error per parameter (``inf`` when not determined).
    ci95 : dict
        95 % interval ``(low, high)`` per parameter.
    correlation : ndarray, shape (6, 6)
        Correlation of (a1, a2, a3, alpha, beta, gamma); NaN rows for parameters
        that are not determined.
    determined : dict
        Per parameter: does the record determine it (95 % half-width < 50 %)?
    derived : dict
        What the record determines even when a1 does not: ``static_gain``
        a3/a1 (µm/V), ``lag`` a2/a1 (s), ``natural_frequency`` sqrt(a1)/2pi (Hz),
        ``damping_ratio``; each ``{"value", "std_err"}``.
    fit_percent : dict
        ``train`` and ``validation`` (None without a validation record) (%);
        over several records, ``100 (1 - ||y - y_model|| / ||y - mean||)`` with
        every sample of every record and each record's own mean.
    residual_rms : float
        Training residual RMS (µm), over all training records.
    residual_rms_validation : float or None
        Validation residual RMS (µm).
    offset : float
        Estimated sensor offset (µm) of the (first) training record, with
        ``offset_std_err``.
    initial_state : tuple of 3 floats
        Estimated (x1, x2, x3) at the (first) record's first sample (µm, µm/s, µm).
    delay_samples : int
        Integer input delay the record needed (0 when none); not part of the
        stage model, applied before fitting.
    dt, n_samples : float, int
        The (first) training record's sample time (s); samples fitted (all records).
    diagnostics : tuple of str
        Plain-language notes, one per poorly determined parameter or problem.
    converged : bool
    reason : str
        Why the optimiser stopped.
    records : tuple of dict
        Per training record: ``source``, ``n_samples``, ``dt``, ``fit_percent``,
        ``residual_rms``, ``offset``, ``offset_std_err`` and ``initial_state``
        (one entry for a single record).
    validation_records : tuple of dict
        Per validation record: ``source``, ``n_samples``, ``dt``, ``fit_percent``,
        ``residual_rms``.
    extensions : dict
        The model extensions tried after the base fit (:mod:`bwdesign.identify.extend`):
        ``chosen`` (names), ``criterion`` (how), ``candidates`` (per extension: chosen
        or not and why, fit and whiteness with it), ``base`` (the same without any).
    disturbance : DisturbanceBound or None
        What the Bouc-Wen model does not explain, as a slowly varying input-equivalent
        disturbance bound (:mod:`bwdesign.identify.unexplained`); ``unexplained`` holds
        how it was computed and the coverage details.
    coverage : float or None
        Share of held-out samples inside the band over the box's corners plus the
        disturbance bound (and sensor noise).
    """

    params: BoucWenParams
    std_err: dict[str, float]
    ci95: dict[str, tuple[float, float]]
    correlation: np.ndarray
    determined: dict[str, bool]
    derived: dict[str, dict[str, float]]
    fit_percent: dict[str, float | None]
    residual_rms: float
    residual_rms_validation: float | None
    offset: float
    offset_std_err: float
    initial_state: tuple[float, float, float]
    delay_samples: int
    dt: float
    n_samples: int
    diagnostics: tuple[str, ...]
    converged: bool
    reason: str
    covariance_method: str
    nfev: int
    n_starts: int
    seconds: float
    level: float = 0.95
    records: tuple[dict[str, Any], ...] = ()
    validation_records: tuple[dict[str, Any], ...] = ()
    traces: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    extensions: dict[str, Any] = field(default_factory=dict)
    disturbance: DisturbanceBound | None = None
    coverage: float | None = None
    unexplained: dict[str, Any] = field(default_factory=dict)

    def to_uncertainty(self) -> UncertaintyBox:
        """The 95 % intervals as an ``[uncertainty]`` box (absolute half-widths).

        Parameters the record does not determine get an infinite half-width:
        the box then refuses to give vertices or samples until a range is
        specified for them.
        """
        widths = {}
        for n in NAMES:
            se = self.std_err[n]
            widths[n] = ("abs", Z95 * se if math.isfinite(se) else math.inf)
        return UncertaintyBox(widths=widths, source="identified", level=self.level)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready document (non-finite numbers stay floats; the JSON layer maps them).

        ``records`` and ``validation_records`` (per-record fit, offset, initial state)
        appear when several records were given.
        """
        corr = [[float(v) for v in row] for row in self.correlation]
        doc = {
            "params": {n: getattr(self.params, n) for n in NAMES},
            "ci95": {n: [float(lo), float(hi)] for n, (lo, hi) in self.ci95.items()},
            "std_err": dict(self.std_err),
            "determined": dict(self.determined),
            "derived": {k: dict(v) for k, v in self.derived.items()},
            "correlation": {"names": list(NAMES), "matrix": corr},
            "fit_percent": dict(self.fit_percent),
            "residual_rms": self.residual_rms,
            "residual_rms_validation": self.residual_rms_validation,
            "offset": self.offset,
            "offset_std_err": self.offset_std_err,
            "initial_state": list(self.initial_state),
            "delay_samples": self.delay_samples,
            "dt": self.dt,
            "n_samples": self.n_samples,
            "diagnostics": list(self.diagnostics),
            "converged": self.converged,
            "reason": self.reason,
            "covariance_method": self.covariance_method,
            "nfev": self.nfev,
            "n_starts": self.n_starts,
            "seconds": self.seconds,
            "level": self.level,
            "extensions": self.extensions,
            "disturbance": (
                None if self.disturbance is None else self.disturbance.to_dict() | self.unexplained
            ),
            "coverage": self.coverage,
        }
        if len(self.records) > 1 or len(self.validation_records) > 1:
            doc["records"] = [dict(r) for r in self.records]
            doc["validation_records"] = [dict(r) for r in self.validation_records]
        return doc


# -- covariance -----------------------------------------------------------------


def _hac_lag(r: np.ndarray) -> int:
    n = r.size
    rc = r - r.mean()
    spec = np.fft.rfft(rc, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec))[:n]
    acf = acf / acf[0] if acf[0] > 0 else acf
    small = np.flatnonzero(np.abs(acf[1:]) < 2.0 / math.sqrt(n))
    lag = int(small[0]) + 1 if small.size else n
    rule = int(4 * (n / 100.0) ** (2.0 / 9.0))
    return int(min(max(lag, rule), max(1, n // 20), 400))


def _covariance(
    jac: np.ndarray, r: np.ndarray, blocks: list[slice] | None = None
) -> tuple[np.ndarray, int]:
    """Newey-West sandwich covariance of the free coordinates, and its (largest) lag.

    Directions of the Jacobian with a singular value below 1e-8 of the largest
    are not determined: every coordinate with weight in them gets an infinite
    variance (and the rest is computed on the determined subspace). ``blocks``:
    the rows of each record (independent records: the Newey-West sum runs within
    each, at its own lag).
    """
    n, p = jac.shape
    _, s, vt = np.linalg.svd(jac, full_matrices=False)
    ok = s > s[0] * 1e-8 if s[0] > 0 else np.zeros_like(s, dtype=bool)
    inv = np.where(ok, 1.0 / np.where(ok, s, 1.0) ** 2, 0.0)
    bread = (vt.T * inv) @ vt
    g_all = jac * r[:, None]
    meat = g_all.T @ g_all
    lags = []
    for b in blocks or [slice(0, n)]:
        g = g_all[b]
        lag = _hac_lag(r[b])
        lags.append(lag)
        for ell in range(1, lag + 1):
            w = 1.0 - ell / (lag + 1.0)
            gam = g[ell:].T @ g[:-ell]
            meat += w * (gam + gam.T)
    lag = max(lags)
    cov = bread @ meat @ bread * (n / max(1, n - p))
    # never narrower than the white-noise s^2 (J^T J)^-1 (Newey-West is biased low
    # in finite samples): per coordinate the larger variance, Newey-West correlation
    s2 = float(r @ r) / max(1, n - p)
    white = np.diag(bread) * s2
    d_hac = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    d_max = np.sqrt(np.maximum(np.diag(cov), white))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.where(np.outer(d_hac, d_hac) > 0, cov / np.outer(d_hac, d_hac), 0.0)
    cov = corr * np.outer(d_max, d_max)
    weight = (vt[~ok] ** 2).sum(axis=0)
    for j in np.flatnonzero(weight > 1e-6):
        cov[j, :] = 0.0
        cov[:, j] = 0.0
        cov[j, j] = math.inf
    return cov, lag


def _natural_jacobian(theta: np.ndarray, p: BoucWenParams) -> np.ndarray:
    t = np.zeros((6, theta.size))
    t[0, IW] = 2 * p.a1
    t[1, ITAU], t[1, IW] = p.a2, 2 * p.a2
    t[2, IK], t[2, IW] = p.a3, 2 * p.a3
    t[3, IA] = p.alpha
    t[4, IB] = p.beta
    t[5, IB], t[5, IQ] = p.gamma, p.beta * (1 - math.tanh(theta[IQ]) ** 2)
    return t


# -- diagnostics ----------------------------------------------------------------


def sandwich_covariance(
    jac: np.ndarray, r: np.ndarray, blocks: list[slice] | None = None
) -> tuple[np.ndarray, int]:
    """The interval machinery of :func:`bwdesign.identify` for another model's fit: the
    Newey-West sandwich covariance of the fitted coordinates (never narrower than the
    white-noise one; undetermined directions infinite) and its lag."""
    return _covariance(jac, r, blocks)


def _monotone_runs(u: np.ndarray) -> tuple[int, float]:
    """Number of input reversals and the largest monotone excursion (V)."""
    du = np.diff(u)
    du = du[du != 0]
    if du.size == 0:
        return 0, 0.0
    s = np.sign(du)
    breaks = np.flatnonzero(s[1:] != s[:-1]) + 1
    runs = np.split(np.abs(du), breaks)
    return int(breaks.size), float(max(r.sum() for r in runs))


def _diagnose(
    *,
    p: BoucWenParams,
    u: list[np.ndarray],
    dt: float,
    rel: dict[str, float],
    corr: np.ndarray,
    derived: dict[str, dict[str, float]],
    resonance_held: tuple[str, float, float, float] | None,
    delay: int,
    theta: np.ndarray,
    r_acf1: tuple[float, float],
    fit_train: float,
) -> list[str]:
    notes: list[str] = []
    f_nyq = 0.5 / dt
    if resonance_held is not None:
        src, wn, rel_w, band = resonance_held
        k, tau = derived["static_gain"], derived["lag"]
        held = {
            "init": "init's value",
            "curvature": "the free fit's value (a guess from the low-frequency curvature)",
            "default": "the stated default max(pi/dt, 2/lag)",
        }[src]
        notes.append(
            f"The resonance and the damping are NOT determined by these data (a free fit "
            f"gives sqrt(a1) a 95 % half-width of {_pct(rel_w)}, and only {band:.2g} of the "
            f"input's power lies within a factor 3 of the resonance it found): the input "
            f"has no usable content near the resonance (the record resolves up to the "
            f"Nyquist frequency {f_nyq:.4g} Hz). a1 is held at {held}, "
            f"{wn / (2 * math.pi):.4g} Hz, and a1, a2 "
            f"and a3 are reported as not determined (infinite intervals). What the data do "
            f"determine: static gain a3/a1 = {k['value']:.6g} ± {Z95 * k['std_err']:.2g} µm/V "
            f"and the effective lag a2/a1 = {tau['value']:.4g} ± {Z95 * tau['std_err']:.2g} s "
            f"(given the held resonance; it also absorbs the sampled response of the real "
            f"one). "
            + (
                "Certificates for this stage file rely on init's a1 and a2: check them "
                "with an identification record that contains the resonance."
                if src == "init"
                else "Before certifying, identify the resonance with `bwdesign excite` at "
                "a sample rate several times above it, or give the stage's a1 with --init."
            )
        )
    runs = [_monotone_runs(uk) for uk in u]
    n_rev, travel = sum(n for n, _ in runs), max(w for _, w in runs)
    sat = 1.0 / (p.beta + p.gamma)
    if not (rel["beta"] < _DETERMINED_REL and rel["gamma"] < _DETERMINED_REL):
        if n_rev == 0:
            why = (
                "the input never reversed, so only one branch of the loop was seen and the "
                "shape parameters beta and gamma are not separable"
            )
        elif travel < 2.0 * sat:
            why = (
                f"the input never travelled far enough between reversals to saturate the "
                f"hysteresis (largest monotone excursion {travel:.3g} V; saturation takes "
                f"about 1/(beta + gamma) = {sat:.3g} V), so beta and gamma are not separable"
            )
        else:
            why = "the record does not separate them"
        notes.append(
            f"beta (95 % half-width {_pct(rel['beta'])}) and gamma ({_pct(rel['gamma'])}) are "
            f"not determined: {why}. Excite large reversals (bwdesign excite)."
        )
    k = NAMES.index
    for name in ("alpha", "a3"):
        if rel[name] >= _DETERMINED_REL and not (name == "a3" and resonance_held):
            c = corr[k("alpha"), k("a3")]
            extra = (
                f" (its correlation with {'a3' if name == 'alpha' else 'alpha'} is {c:.3f}: "
                "with little hysteresis visible, only the net slope a3/a1 - alpha is fitted)"
                if math.isfinite(c) and abs(c) > 0.9
                else ""
            )
            notes.append(f"{name} is not determined (95 % half-width {_pct(rel[name])}){extra}.")
    if resonance_held is None:
        for name in ("a1", "a2"):
            if rel[name] >= _DETERMINED_REL:
                notes.append(
                    f"{name} is not determined (95 % half-width {_pct(rel[name])}): the "
                    "excitation has little content near the resonance, so it is a guess."
                )
    if abs(theta[IQ]) > Q_MAX - 1e-3:
        notes.append(
            "gamma/beta reached the edge of the bounded class (|gamma| = beta): the loop "
            "shape is at the class boundary; check the data."
        )
    if delay:
        notes.append(
            f"An input delay of {delay} sample(s) ({1e3 * delay * dt:.4g} ms) was needed and "
            "applied before fitting (a logger that stamps y at the start of the sample gives "
            "one). The stage model has no delay: the controller must account for it."
        )
    acf1, frac_out = r_acf1
    if acf1 > 0.3 or frac_out > 0.25:
        notes.append(
            f"The residuals are not white (lag-1 autocorrelation {acf1:.2f}; "
            f"{100 * frac_out:.0f} % of lags 1-50 outside the ±2/sqrt(N) band, about 5 % "
            f"for white noise; fit {fit_train:.2f} %): the model misses part of the "
            "behaviour (an amplifier lag, creep, a second mode, a drifting sensor). The "
            "parameters may be biased well beyond their intervals, which are Newey-West "
            "corrected but cannot cover a wrong model."
        )
    return notes


def _hz_range(f: list[float]) -> str:
    return f"{f[0]:.4g} Hz" if len(f) == 1 else f"{f[0]:.4g} to {f[-1]:.4g} Hz"


def _pct(rel: float) -> str:
    return "infinite" if not math.isfinite(rel) else f"{100 * rel:.3g} %"


# -- assembly -------------------------------------------------------------------


def validate_record(prob: Problem, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Re-estimate offset and initial state on a validation record, parameters held.

    Returns the model output and the record's fit vector."""
    from .solve import solve

    free = np.zeros(10, dtype=bool)
    free[[IOFF, IZ, IE1, IE2]] = True
    cost, th = prob.project(theta)
    th[[IK, IA]] = theta[[IK, IA]]
    lo, hi = np.full(10, -np.inf), np.full(10, np.inf)
    lo[IZ], hi[IZ] = -5.0, 5.0
    best = None
    for z in (-0.8, 0.0, 0.8):
        th0 = th.copy()
        th0[IZ] = z
        th_z, sol = solve(prob, th0, free, (lo, hi), max_nfev=50)
        if best is None or sol.cost < best[1]:
            best = (th_z, sol.cost)
    return prob.predict(best[0]), best[0]


@dataclass(frozen=True)
class FitOutcome:
    """Where the search of :func:`bwdesign.identify.identify` ended, and how it got there.

    Attributes
    ----------
    theta : ndarray
        The optimum (fit coordinates, :mod:`bwdesign.identify.problem`).
    free : ndarray of bool
        Coordinates whose uncertainty is reported (the resonance free even when held).
    sol : scipy.optimize.OptimizeResult
        The optimiser's answer at ``theta``.
    delay : int
        Input delay (samples).
    resonance_held : (source, wn, rel, band) or None
        A resonance the record does not determine, held at ``wn`` (rad/s).
    alternatives : list of ndarray
        Other resonances that fit the record as well (they widen the intervals).
    nfev, n_starts : int
        Residual evaluations and refinements spent.
    seconds : float
        Wall time of the search.
    """

    theta: np.ndarray
    free: np.ndarray
    sol: Any
    delay: int
    resonance_held: tuple[str, float, float, float] | None
    alternatives: list[np.ndarray]
    nfev: int
    n_starts: int
    seconds: float


def residual_whiteness(rc: np.ndarray) -> tuple[float, float]:
    """Lag-1 autocorrelation of a (centred) residual and the share of lags 1-50 outside
    the ±2/sqrt(N) band of white noise (about 5 % for white noise)."""
    energy = float(rc @ rc)
    lags = range(1, min(51, rc.size))
    acf = np.array([rc[k:] @ rc[:-k] for k in lags]) / energy if energy > 0 else np.zeros(1)
    return float(acf[0]), float(np.mean(np.abs(acf) > 2.0 / math.sqrt(rc.size)))


def pooled_fit(ys: list[np.ndarray], models: list[np.ndarray]) -> float:
    """Fit percent over several records, each about its own mean (one record: fit_percent)."""
    if len(ys) == 1:
        return fit_percent(ys[0], models[0])
    num = sum(float(np.sum((y - m) ** 2)) for y, m in zip(ys, models, strict=True))
    den = sum(float(np.sum((y - np.mean(y)) ** 2)) for y in ys)
    return float(100.0 * (1.0 - math.sqrt(num / den)))


def _rms(ys: list[np.ndarray], models: list[np.ndarray]) -> float:
    res = np.concatenate([m - y for y, m in zip(ys, models, strict=True)])
    return float(np.sqrt(np.mean(res**2)))


def _summary(rec: Any, y_model: np.ndarray) -> dict[str, Any]:
    return {
        "source": rec.source,
        "n_samples": rec.n,
        "dt": rec.dt,
        "fit_percent": fit_percent(rec.y, y_model),
        "residual_rms": _rms([rec.y], [y_model]),
    }


def _train_records(
    prob: Stack, theta: np.ndarray, p: BoucWenParams, sd: np.ndarray, data: list, models: list
) -> list[dict[str, Any]]:
    """Per training record: fit, offset (and its standard error) and initial state."""
    out = []
    wn = math.sqrt(p.a1)
    for k, (pk, rec) in enumerate(zip(prob.problems, data, strict=True)):
        th = prob.local(theta, k)
        h0 = float(th[IZ] * p.alpha / (p.beta + p.gamma))
        w0 = p.static_gain * float(pk.u[0]) - h0
        x0 = (w0 + pk.y_scale * float(th[IE1]), pk.y_scale * wn * float(th[IE2]), h0)
        i_off = IOFF if prob.n_records == 1 else int(prob.i_off[k])
        out.append(
            _summary(rec, models[k])
            | {
                "offset": pk.y_mean + pk.y_scale * float(th[IOFF]),
                "offset_std_err": pk.y_scale * float(sd[i_off]),
                "initial_state": x0,
            }
        )
    return out


def _validation(
    validation: list, prob: Stack, theta: np.ndarray, delay: int, traces: dict
) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
    """Each validation record's model output (offset and initial state re-estimated)."""
    models, summaries = [], []
    for j, rec in enumerate(validation):
        u_in, known = prob.validation_inputs(rec, delay, theta)
        vprob = Problem(u_in, rec.y - known, rec.dt, prob.sign)
        v_model = validate_record(vprob, prob.local(theta, 0))[0] + known
        models.append(v_model)
        summaries.append(_summary(rec, v_model))
        pre = "val_" if j == 0 else f"val{j + 1}_"
        traces.update({pre + "t": rec.t, pre + "u": rec.u, pre + "y": rec.y})
        traces[pre + "y_model"] = v_model
    return models, summaries


def build_result(
    prob: Stack, fit: FitOutcome, *, data: list, validation: list, name: str
) -> IdentificationResult:
    """Covariance, intervals, fit quality and diagnostics at the optimum ``fit.theta``.

    ``data``, ``validation``: the training and validation records (lists).
    """
    theta, sol, delay = fit.theta, fit.sol, fit.delay
    p = params_from_theta(theta, prob.sign, name)
    r = prob.residual(theta)
    alt = [params_from_theta(th, prob.sign) for th in fit.alternatives]
    unc = _uncertainty(prob, fit, p, r, alt)
    models = prob.predict_each(theta)
    ys = [pk.y for pk in prob.problems]
    fit_train = pooled_fit(ys, models)
    whiteness = residual_whiteness(prob.centre(r))
    traces = {}
    for k, rec in enumerate(data):
        pre = "" if k == 0 else f"r{k + 1}_"
        traces.update({pre + "t": rec.t, pre + "u": rec.u, pre + "y": rec.y})
        traces[pre + "y_model"] = models[k]
    v_models, v_summaries = _validation(validation, prob, theta, delay, traces)
    v_ys = [rec.y for rec in validation]
    notes = _diagnose(
        p=p,
        u=[rec.u for rec in data],
        dt=prob.dt,
        rel=unc.rel,
        corr=unc.corr,
        derived=unc.derived,
        resonance_held=fit.resonance_held,
        delay=delay,
        theta=theta,
        r_acf1=whiteness,
        fit_train=fit_train,
    )
    if fit.alternatives:
        notes.append(_widened_note(alt, unc.widened))
    converged, reason = _convergence(sol, unc.values)
    records = _train_records(prob, theta, p, unc.sd, data, models)
    return IdentificationResult(
        params=p,
        std_err=unc.se,
        ci95=unc.ci,
        correlation=unc.corr,
        determined=unc.determined,
        derived=unc.derived,
        fit_percent={
            "train": fit_train,
            "validation": pooled_fit(v_ys, v_models) if validation else None,
        },
        residual_rms=_rms(ys, models),
        residual_rms_validation=_rms(v_ys, v_models) if validation else None,
        offset=records[0]["offset"],
        offset_std_err=records[0]["offset_std_err"],
        initial_state=records[0]["initial_state"],
        delay_samples=delay,
        dt=data[0].dt,
        n_samples=prob.n,
        diagnostics=tuple(notes),
        converged=converged,
        reason=reason,
        covariance_method=(
            f"Newey-West sandwich (Bartlett weights, lag {unc.lag} samples) on the Jacobian at "
            "the optimum, each variance at least the white-noise s^2 (J^T J)^-1; delta "
            "method to a1..gamma"
        ),
        nfev=fit.nfev,
        n_starts=fit.n_starts,
        seconds=fit.seconds,
        records=tuple(records),
        validation_records=tuple(v_summaries),
        traces=traces,
    )


@dataclass(frozen=True)
class _Uncertainty:
    """Standard errors, intervals and correlations of the six parameters and derived values."""

    values: dict[str, float]
    se: dict[str, float]
    rel: dict[str, float]
    ci: dict[str, tuple[float, float]]
    determined: dict[str, bool]
    corr: np.ndarray
    derived: dict[str, dict[str, float]]
    widened: list[str]
    sd: np.ndarray
    lag: int


def _uncertainty(
    prob: Stack, fit: FitOutcome, p: BoucWenParams, r: np.ndarray, alt: list[BoucWenParams]
) -> _Uncertainty:
    """The covariance at the optimum, mapped to a1..gamma and widened by the alternatives."""
    theta, free = fit.theta, fit.free
    jac = prob.jacobian(theta, free, central=True)
    # coordinates held in the fit (an amplifier lag) join the covariance: marginal intervals
    held = prob.held_jacobian(theta)
    cov_all, lag = _covariance(
        np.hstack([jac, held]), r, prob.blocks() if prob.n_records > 1 else None
    )
    cov_free = cov_all[: jac.shape[1], : jac.shape[1]]
    cov = np.zeros((theta.size, theta.size))
    idx = np.flatnonzero(free)
    cov[np.ix_(idx, idx)] = cov_free
    tn = _natural_jacobian(theta, p)
    bad = ~np.isfinite(np.diag(cov))
    cov_ok = np.where(np.isfinite(cov), cov, 0.0)
    cov6 = tn @ cov_ok @ tn.T
    var = np.clip(np.diag(cov6), 0.0, None)
    inf6 = (np.abs(tn[:, bad]) > 0).any(axis=1)
    var = np.where(inf6 | ~np.isfinite(var), math.inf, var)
    se = {n: float(math.sqrt(v)) for n, v in zip(NAMES, var, strict=True)}
    if fit.resonance_held is not None:
        for n in ("a1", "a2", "a3"):
            se[n] = math.inf
    values = {n: float(getattr(p, n)) for n in NAMES}
    rel = {n: (Z95 * se[n] / abs(values[n]) if values[n] != 0 else math.inf) for n in NAMES}
    for n in NAMES:
        if not math.isfinite(rel[n]) or rel[n] > 1e6:
            se[n], rel[n] = math.inf, math.inf
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.sqrt(var)
        corr = cov6 / np.outer(d, d)
    for i, n in enumerate(NAMES):
        if not math.isfinite(se[n]) or var[i] == 0:
            corr[i, :] = np.nan
            corr[:, i] = np.nan
    widened = []
    for n in NAMES:
        spread = max((abs(getattr(q, n) - values[n]) for q in alt), default=0.0)
        if math.isfinite(se[n]) and spread > Z95 * se[n]:
            se[n] = spread / Z95
            rel[n] = Z95 * se[n] / abs(values[n]) if values[n] else math.inf
            widened.append(n)
    ci = {n: (values[n] - Z95 * se[n], values[n] + Z95 * se[n]) for n in NAMES}
    determined = {n: bool(rel[n] < _DETERMINED_REL) for n in NAMES}
    sd = np.sqrt(np.clip(np.where(np.isfinite(np.diag(cov)), np.diag(cov), np.inf), 0.0, None))
    derived = _derived(p, cov, sd, alt, held=fit.resonance_held is not None)
    return _Uncertainty(values, se, rel, ci, determined, corr, derived, widened, sd, lag)


def _derived(
    p: BoucWenParams, cov: np.ndarray, sd: np.ndarray, alt: list[BoucWenParams], *, held: bool
) -> dict[str, dict[str, float]]:
    """Static gain, lag, natural frequency and damping ratio with their standard errors."""
    k = p.static_gain
    tau = p.a2 / p.a1
    wn = math.sqrt(p.a1)
    zeta = 0.5 * tau * wn
    var_logzeta = cov[ITAU, ITAU] + cov[IW, IW] + 2 * cov[ITAU, IW]
    derived = {
        "static_gain": {"value": k, "std_err": abs(k) * float(sd[IK])},
        "lag": {"value": tau, "std_err": tau * float(sd[ITAU])},
        "natural_frequency": {
            "value": wn / (2 * math.pi),
            "std_err": math.inf if held else wn / (2 * math.pi) * float(sd[IW]),
        },
        "damping_ratio": {
            "value": zeta,
            "std_err": math.inf if held else zeta * math.sqrt(max(var_logzeta, 0.0)),
        },
    }
    for key, get in (("static_gain", lambda q: q.static_gain), ("lag", lambda q: q.a2 / q.a1)):
        spread = max((abs(get(q) - derived[key]["value"]) for q in alt), default=0.0)
        derived[key]["std_err"] = max(derived[key]["std_err"], spread / Z95)
    return derived


def _widened_note(alt: list[BoucWenParams], widened: list[str]) -> str:
    f_alt = sorted(math.sqrt(q.a1) / (2 * math.pi) for q in alt)
    extra = f" (widened: {', '.join(widened)})" if widened else ""
    return (
        f"With the resonance at {_hz_range(f_alt)} the record is fitted as well "
        f"({len(alt)} refit(s) within the chi-square 95 % misfit): the intervals "
        f"and the static gain's and lag's standard errors cover those estimates too{extra}."
    )


def _convergence(sol: Any, values: dict[str, float]) -> tuple[bool, str]:
    """``(converged, reason)``: the fit met the step test and the optimum is finite."""
    finite = all(math.isfinite(v) for v in values.values()) and math.isfinite(sol.cost)
    converged = bool(sol.status > 0 and finite)
    reason = str(sol.message) if finite else "the optimum is not finite"
    if not converged:
        reason += (
            "; what would help: a start closer to the stage (--init), a record with larger "
            "reversals and content near the resonance (bwdesign excite), or more "
            "evaluations (--max-nfev)"
        )
    return converged, reason
