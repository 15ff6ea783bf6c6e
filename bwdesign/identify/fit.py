"""Output-error identification of the Bouc-Wen stage from one measured record.

Steps (each is seeded and deterministic):

1. **Start from the data.** With the linear dynamics at a neutral default, a
   grid over the hysteresis shape (beta times the input range, gamma/beta and
   the initial hysteresis state) is solved for gain, alpha, offset and initial
   state by linear least squares (the model is linear in them: ``h`` scales
   with ``alpha``). A second grid over resonance and damping follows, then
   the hysteresis grid once more.
2. **Refine** all coordinates of :mod:`bwdesign.identify.problem` with
   ``scipy.optimize.least_squares`` (trust-region reflective) from the best
   start and from seeded perturbations of it (``multistart``).
3. **Identifiability.** If the resonance is not determined by the data (its
   95 % half-width exceeds 50 %, or less than 1e-5 of the input's power lies
   between a third and three times it, as on a slow sine: a local interval
   alone can look tight on such data while the truth lies elsewhere) it is
   held at the prior: ``init``'s a1; else the free fit's value when that lies
   below the Nyquist frequency with a tight local interval (the low-frequency
   curvature of the response placed it); else the stated default
   ``wn = max(pi/dt, 2/tau)``, at or above the Nyquist frequency and at least
   critically damped for the fitted lag. The rest is refitted and a1, a2, a3
   are reported as not determined. The fit is repeated with the resonance at
   0.5 to 32 times the held value; every one that fits the record as well
   (misfit within the chi-square 95 % quantile of noise variances) widens the
   other intervals to cover its estimates (a local interval alone would
   pretend the resonance is known).
4. **Intervals** from the Jacobian at the optimum (see
   :mod:`bwdesign.identify.result`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ..errors import InputError
from ..model.params import BoucWenParams
from ..validate import Range, integer
from .data import IdentificationData
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
    delayed_input,
    theta_from_params,
)
from .result import FitOutcome, IdentificationResult, build_result

__all__ = ["identify", "NAMES"]

NAMES = ("a1", "a2", "a3", "alpha", "beta", "gamma")
#: A coordinate is "determined" when its 95 % half-width is below this fraction.
DETERMINED_REL = 0.5
_DELAYS = (0, 1, 2, 3)
#: Supported number of refinements of the fit (the derived start counts as one).
MULTISTART = Range(1, math.inf)
#: Least share of the input's power within a third and three times the fitted
#: resonance for the resonance to count as seen (besides a tight interval).
MIN_BAND_FRACTION = 1e-5
#: Resonances (times the held one) refitted to see which fit the record as well.
_PROFILE_FACTORS = (0.5, 2.0, 4.0, 8.0, 16.0, 32.0)
#: chi-square(1) 95 % quantile: the misfit increase (in noise variances) that still fits.
_CHI2_95 = 3.84
#: chi-square(1) quantile at 0.999: the misfit drop a delay must buy.
_LR_DELAY = 10.83


def _resolve_init(init: str | BoucWenParams | None) -> BoucWenParams | None:
    if init is None or isinstance(init, BoucWenParams):
        return init
    from ..model.config import load_plant

    return load_plant(init)


def _free_mask(fixed: Iterable[str], init: BoucWenParams | None) -> np.ndarray:
    fixed = set(fixed)
    unknown = sorted(fixed - set(NAMES))
    if unknown:
        raise InputError(
            f"fixed: unknown parameter(s) {', '.join(unknown)}; use {', '.join(NAMES)}"
        )
    if fixed and init is None:
        raise InputError("fixed parameters need init= (the values to hold them at)")
    for name, needs in (("a2", "a1"), ("a3", "a1"), ("gamma", "beta")):
        if name in fixed and needs not in fixed:
            raise InputError(
                f"fixed: {name} can be held only together with {needs} (the fit works in "
                "a3/a1, a2/a1, sqrt(a1) and gamma/beta)"
            )
    free = np.ones(10, dtype=bool)
    for name, idx in (("a1", IW), ("alpha", IA), ("beta", IB), ("gamma", IQ)):
        if name in fixed:
            free[idx] = False
    if "a2" in fixed:
        free[ITAU] = False
    if "a3" in fixed:
        free[IK] = False
    return free


def _grid_hysteresis(
    prob: Problem, base: np.ndarray, free: np.ndarray
) -> list[tuple[float, np.ndarray]]:
    """Score a grid of hysteresis shapes (beta range, gamma/beta, h0) by linear projection."""
    u_range = float(np.ptp(prob.u))
    betas = np.geomspace(0.3, 100.0, 9) / u_range if free[IB] else [math.exp(base[IB])]
    qs = (-1.0, 0.0, 1.0) if free[IQ] else (base[IQ],)
    out = []
    for beta in betas:
        for q in qs:
            for z in (-0.8, 0.0, 0.8):
                th = base.copy()
                th[IB], th[IQ], th[IZ] = math.log(beta), q, z
                cost, th = prob.project(th)
                out.append((cost, th))
    out.sort(key=lambda c: c[0])
    return out


def _grid_linear(prob: Problem, base: np.ndarray, free: np.ndarray) -> tuple[float, np.ndarray]:
    """Score a grid of resonance x damping by linear projection at a fixed hysteresis shape."""
    nyq = math.pi / prob.dt
    duration = prob.u.size * prob.dt
    wns = (
        np.geomspace(max(2.0 * math.pi * 2.0 / duration, nyq * 1e-3), 10.0 * nyq, 28)
        if free[IW]
        else [math.exp(base[IW])]
    )
    zetas = (0.02, 0.06, 0.2, 0.6, 1.5) if free[ITAU] else (None,)
    h_unit = prob.unit_hysteresis(base)
    best = (math.inf, base)
    for wn in wns:
        for zeta in zetas:
            th = base.copy()
            th[IW] = math.log(wn)
            if zeta is not None:
                th[ITAU] = math.log(2.0 * zeta / wn)
            cost, th = prob.project(th, h_unit)
            if cost < best[0]:
                best = (cost, th)
    return best


def _start(
    data: IdentificationData, init: BoucWenParams | None, free: np.ndarray
) -> tuple[np.ndarray, float, float]:
    """Start vector, gain sign and its cost, derived from the data (and init)."""
    coef = np.polyfit(data.u, data.y, 1)
    sign = math.copysign(1.0, coef[0]) if init is None else math.copysign(1.0, init.a3)
    if init is not None:
        base, sign = theta_from_params(init)
    else:
        wn = 0.5 * math.pi / data.dt
        base = np.zeros(10)
        base[IW] = math.log(wn)
        base[ITAU] = math.log(2.0 * 0.7 / wn)
        base[IB] = math.log(1.0 / float(np.ptp(data.u)))
    prob = Problem(data.u, data.y, data.dt, sign)
    if init is not None:
        # keep init's values; only the offset and initial state from the data
        th = base.copy()
        scores = []
        for z in (-0.8, 0.0, 0.8):
            trial = th.copy()
            trial[IZ] = z
            scores.append((prob.project(trial)[0], z))
        th[IZ] = min(scores)[1]
        cost, proj = prob.project(th)
        th[IOFF], th[IE1], th[IE2] = proj[IOFF], proj[IE1], proj[IE2]
        return th, sign, cost
    th = _grid_hysteresis(prob, base, free)[0][1]
    th = _grid_linear(prob, th, free)[1]
    cost, th = _grid_hysteresis(prob, th, free)[0]
    return th, sign, cost


def _bounds(start: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lo = np.full(10, -np.inf)
    hi = np.full(10, np.inf)
    for i in (IK, ITAU, IW, IA, IB):
        lo[i], hi[i] = start[i] - 12.0, start[i] + 12.0
    lo[IQ], hi[IQ] = -Q_MAX, Q_MAX
    lo[IZ], hi[IZ] = -5.0, 5.0
    return lo[free], hi[free]


def _refine(prob: Problem, start: np.ndarray, free: np.ndarray, max_nfev: int):
    lo, hi = _bounds(start, free)
    x0 = np.clip(start[free], lo + 1e-9, hi - 1e-9)

    def full(x: np.ndarray) -> np.ndarray:
        th = start.copy()
        th[free] = x
        return th

    sol = least_squares(
        lambda x: prob.residual(full(x)),
        x0,
        jac=lambda x: prob.jacobian(full(x), free),
        bounds=(lo, hi),
        method="trf",
        x_scale=1.0,
        xtol=1e-10,
        ftol=1e-12,
        gtol=1e-10,
        max_nfev=max_nfev,
    )
    return full(sol.x), sol


def _multistart(
    prob: Problem,
    start: np.ndarray,
    free: np.ndarray,
    *,
    multistart: int,
    seed: int,
    max_nfev: int,
    say: Callable[[str], None],
):
    rng = np.random.default_rng(seed)
    best = None
    total = 0
    for i in range(max(1, multistart)):
        th0 = start.copy()
        if i > 0:
            scale = np.zeros(10)
            scale[[IK, ITAU, IW, IA, IB]] = 0.3
            scale[IQ] = 0.5
            scale[IZ] = 0.3
            th0 = th0 + np.where(free, scale * rng.standard_normal(10), 0.0)
            th0[IQ] = float(np.clip(th0[IQ], -Q_MAX + 0.1, Q_MAX - 0.1))
        th, sol = _refine(prob, th0, free, max_nfev)
        total += sol.nfev
        say(f"  start {i + 1}/{multistart}: cost {2 * sol.cost:.6g} after {sol.nfev} evaluations")
        if best is None or sol.cost < best[1].cost:
            best = (th, sol)
    return best[0], best[1], total


def identify(
    data: IdentificationData,
    *,
    validation: IdentificationData | None = None,
    init: str | BoucWenParams | None = None,
    fixed: Iterable[str] = (),
    multistart: int = 3,
    seed: int = 0,
    max_nfev: int = 200,
    name: str = "identified",
    progress: Callable[[str], None] | None = None,
) -> IdentificationResult:
    """Fit (a1, a2, a3, alpha, beta, gamma) to a measured record (output error, exact ZOH model).

    Parameters
    ----------
    data : IdentificationData
        Training record (:func:`bwdesign.identify.load_data` or
        :meth:`IdentificationData.from_arrays`); t in s, u in V, y in µm.
    validation : IdentificationData, optional
        Held-out record: the fit percent on it is reported (its offset and
        initial state are re-estimated with the parameters held).
    init : str or BoucWenParams, optional
        Preset name, stage TOML or parameters to start from (and the prior for
        a resonance the data do not determine). Without it the start is derived
        from the data.
    fixed : iterable of str
        Parameters held at ``init``'s values (a2 and a3 only with a1, gamma only
        with beta).
    multistart : int
        Number of refinements: the derived start and ``multistart - 1`` seeded
        perturbations of it; the best is kept.
    seed : int
        Seed of the perturbations.
    max_nfev : int
        Residual evaluations allowed per refinement.
    name : str
        Name of the identified plant.
    progress : callable, optional
        Receives one line per step (the command line prints them on stderr).

    Returns
    -------
    IdentificationResult
        ``converged`` is False (with ``reason``) when the optimiser stopped
        without meeting its tolerances or the result is not finite.
    """
    say = progress or (lambda _msg: None)
    if not isinstance(data, IdentificationData):
        raise InputError("data must be an IdentificationData (use bwdesign.identify.load_data)")
    if validation is not None and not isinstance(validation, IdentificationData):
        raise InputError("validation must be an IdentificationData")
    if validation is not None and abs(validation.dt - data.dt) > 1e-3 * data.dt:
        raise InputError(
            f"validation record is sampled at {validation.dt:.6g} s, the training record at "
            f"{data.dt:.6g} s: they must share the sample time"
        )
    multistart = integer(multistart, "multistart", within=MULTISTART)
    tic = time.perf_counter()
    prior = _resolve_init(init)
    free = _free_mask(fixed, prior)
    say(f"identify: {data.n} samples at dt = {data.dt:.6g} s; deriving a start from the data")
    start, sign, cost0 = _start(data, prior, free)
    say(f"  start cost {cost0:.6g}")
    prob = Problem(data.u, data.y, data.dt, sign)
    theta, sol, nfev = _multistart(
        prob, start, free, multistart=multistart, seed=seed, max_nfev=max_nfev, say=say
    )
    fit = _Fit(prob, theta, sol, free, nfev)
    delay = _search_delay(fit, data, max_nfev, say)
    resonance_held, alternatives = None, []
    if fit.free[IW]:
        resonance_held, alternatives = _resonance(fit, data, prior, max_nfev, say)
    # intervals with the resonance free even when it is held: they must not pretend
    # that a resonance the record cannot see is known
    cov_free = fit.free.copy()
    cov_free[IW] = cov_free[IW] or resonance_held is not None
    outcome = FitOutcome(
        theta=fit.theta,
        free=cov_free,
        sol=fit.sol,
        delay=delay,
        resonance_held=resonance_held,
        alternatives=alternatives,
        nfev=fit.nfev,
        n_starts=multistart,
        seconds=time.perf_counter() - tic,
    )
    return build_result(fit.prob, outcome, data=data, validation=validation, name=name)


@dataclass
class _Fit:
    """The search so far: the problem (input delay), the optimum, what is free, the cost."""

    prob: Problem
    theta: np.ndarray
    sol: Any
    free: np.ndarray
    nfev: int


def _search_delay(fit: _Fit, data: IdentificationData, max_nfev: int, say) -> int:
    """The input delay (samples) that earns its place; ``fit`` moves to it."""
    delay = 0
    for d in _DELAYS[1:]:
        # a delay must earn its place: a likelihood-ratio gain above chi2(1, 0.999)
        trial = Problem(delayed_input(data.u, d), data.y, data.dt, fit.prob.sign)
        th_d, sol_d = _refine(trial, fit.theta, fit.free, max_nfev)
        fit.nfev += sol_d.nfev
        if not data.n * math.log(fit.sol.cost / max(sol_d.cost, 1e-300)) > _LR_DELAY:
            break
        say(f"  input delay {d} sample(s): cost {2 * sol_d.cost:.6g}")
        delay, fit.theta, fit.sol, fit.prob = d, th_d, sol_d, trial
    return delay


def _resonance(
    fit: _Fit, data: IdentificationData, prior: BoucWenParams | None, max_nfev: int, say
) -> tuple[tuple[str, float, float, float] | None, list[np.ndarray]]:
    """Whether the record determines the resonance; if not, hold it and profile it.

    Returns ``(resonance_held, alternatives)``: ``(source, wn, rel, band)`` of a held
    resonance (``fit`` refitted with it held unless the record's own curvature placed
    it) and the other resonances that fit the record as well (they widen the intervals).
    """
    theta, prob = fit.theta, fit.prob
    alternatives: list[np.ndarray] = []
    rel = _rel_halfwidth(prob, theta, fit.free, IW)
    f_r = math.exp(theta[IW]) / (2 * math.pi)
    band = _band_fraction(data.u, data.dt, f_r / 3.0, 3.0 * f_r)
    say(f"  resonance {f_r:.4g} Hz: input power within [f/3, 3f]: {band:.3g} of the total")
    if rel < DETERMINED_REL and band >= MIN_BAND_FRACTION:
        return None, alternatives
    tau = math.exp(theta[ITAU])
    if prior is not None:
        src, wn_hold = "init", math.sqrt(prior.a1)
    elif rel < DETERMINED_REL and f_r < 0.5 / data.dt:
        # the low-frequency curvature placed it inside the record's band: a
        # guess worth keeping, but not a determination
        src, wn_hold = "curvature", math.exp(theta[IW])
    else:
        src, wn_hold = "default", max(math.pi / data.dt, 2.0 / tau)
    say(
        f"  the resonance is not determined by these data (95 % half-width "
        f"{100 * rel:.3g} % of sqrt(a1)); holding it at {wn_hold / (2 * math.pi):.4g} Hz"
    )
    if src != "curvature":  # else keep the free fit (and its wider intervals)
        fit.free = fit.free.copy()
        fit.free[IW] = False
        theta = theta.copy()
        theta[IW] = math.log(wn_hold)
        fit.theta, fit.sol = _refine(prob, theta, fit.free, max_nfev)
        fit.nfev += fit.sol.nfev
    # profile: other resonances that fit the record as well widen the intervals
    held = fit.free.copy()
    held[IW] = False
    s2 = 2.0 * fit.sol.cost / max(1, data.n - int(held.sum()))
    for factor in _PROFILE_FACTORS:
        th_k = fit.theta.copy()
        th_k[IW] += math.log(factor)
        th_k, sol_k = _refine(prob, th_k, held, max_nfev)
        fit.nfev += sol_k.nfev
        if 2.0 * (sol_k.cost - fit.sol.cost) <= _CHI2_95 * s2:
            alternatives.append(th_k)
    say(f"  {len(alternatives)} other resonance(s) fit as well: intervals widened")
    return (src, wn_hold, rel, band), alternatives


def _band_fraction(u: np.ndarray, dt: float, f_lo: float, f_hi: float) -> float:
    """Share of the power of the detrended input within ``[f_lo, f_hi]`` Hz."""
    k = np.arange(u.size)
    x = (u - np.polyval(np.polyfit(k, u, 1), k)) * np.hanning(u.size)  # Hann: little leakage
    power = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(u.size, dt)
    total = float(power[1:].sum())
    if total == 0.0:
        return 0.0
    return float(power[(f >= f_lo) & (f <= f_hi)].sum() / total)


def _rel_halfwidth(prob: Problem, theta: np.ndarray, free: np.ndarray, index: int) -> float:
    """95 % half-width of exp(theta[index]) relative to its value (white-noise estimate)."""
    jac = prob.jacobian(theta, free)
    r = prob.residual(theta)
    dof = max(1, r.size - int(free.sum()))
    s2 = float(r @ r) / dof
    u, s, vt = np.linalg.svd(jac, full_matrices=False)
    floor = s[0] * 1e-12
    inv = 1.0 / np.maximum(s, floor) ** 2
    var = (vt.T**2 @ inv) * s2
    col = int(np.flatnonzero(free).tolist().index(index))
    sd = math.sqrt(var[col])
    return 1.96 * sd if sd < 10 else math.inf
