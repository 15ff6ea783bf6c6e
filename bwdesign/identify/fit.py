"""Output-error identification of the Bouc-Wen stage from one or several measured records.

Several records (any amplitudes, frequencies and sample rates) are fitted as one
:class:`~bwdesign.identify.stack.Stack`: one parameter set, an offset and an
initial state per record. Every step below then runs over all of them: the
quasi-static decision and the start grids use the union (a record with power
near the resonance frees it for all), the sample time in the defaults is the
smallest one, the input delay (in samples) is common to the records.

Steps (each is seeded and deterministic):

1. **Start from the data.** With the linear dynamics at a neutral default, a
   grid over the hysteresis shape (beta times the input range, gamma/beta, then
   the initial hysteresis state) is solved for gain, alpha, offset and initial
   state by linear least squares (the model is linear in them: ``h`` scales
   with ``alpha``).
2. **Quasi-static first.** When the input has less than
   :data:`MIN_BAND_FRACTION` of its power above a third of the starting
   resonance (init's, else a quarter of the Nyquist frequency), as on a slow
   sine far below it, the record cannot place the resonance: it is held from
   the start (init's a1, else the stated default ``wn = max(pi/dt, 2/tau)``, at
   or above the Nyquist frequency and at least critically damped for the
   fitted lag) and the quasi-static model (gain, lag, hysteresis, offset,
   initial state) is fitted. A score test then asks whether freeing the
   resonance would lower the misfit by more than chi-square(1, 0.999); only then
   is it fitted. Otherwise a grid over resonance and damping and the
   hysteresis grid once more give the start of the full model.
3. **Refine** with :func:`bwdesign.identify.solve.solve` (Levenberg-Marquardt,
   exact Jacobian, the offset in closed form, converged when the remaining
   step is a small fraction of a standard error in every determined
   direction) from the start and from ``multistart - 1`` seeded perturbations
   of the optimum (a perturbation that ends lower replaces it).
4. **Identifiability.** A resonance found free but with a 95 % half-width over
   50 % or less than 1e-5 of the input's power between a third and three
   times it is held as above (or at the free fit's value when that lies below
   the Nyquist frequency with a tight local interval: the low-frequency
   curvature placed it); a1, a2, a3 are reported as not determined. The fit is
   repeated with the resonance at 0.5 to 32 times the held value; every one
   that fits the record as well (misfit within the chi-square 95 % quantile of
   noise variances) widens the other intervals to cover its estimates.
5. **Intervals** from the Jacobian at the optimum (see
   :mod:`bwdesign.identify.result`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams
from ..validate import Range, integer
from .data import IdentificationData
from .extend import make_context, select_extensions
from .extstack import CREEP_TAUS
from .problem import (
    IA,
    IB,
    IK,
    IQ,
    ITAU,
    IW,
    IZ,
    Q_MAX,
    theta_from_params,
)
from .result import FitOutcome, IdentificationResult, build_result
from .solve import STEP_TOL, Solution, solve
from .stack import Stack
from .unexplained import coverage_note, unexplained

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
#: Samples the start grids score (the fit itself uses the whole record).
START_SAMPLES = 10_000
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


def _grid_hysteresis(prob: Stack, base: np.ndarray, free: np.ndarray) -> tuple[float, np.ndarray]:
    """Best hysteresis shape (beta range x gamma/beta x h0) by linear projection.

    Several records: one h0 for all on the grid, then each record's h0 in turn.
    """
    betas = np.geomspace(0.3, 100.0, 9) / prob.u_range if free[IB] else [math.exp(base[IB])]
    qs = (-1.0, 0.0, 1.0) if free[IQ] else (base[IQ],)
    grid = []
    for beta in betas:
        for q in qs:
            for z in (-0.8, 0.0, 0.8):
                th = base.copy()
                th[IB], th[IQ], th[prob.i_z] = math.log(beta), q, z
                grid.append(th)
    best = None  # ties (all infinite: no positive gain and alpha) keep the first point
    for scored in prob.project_many(grid):
        if best is None or scored[0] < best[0]:
            best = scored
    for k in range(prob.n_records if prob.n_records > 1 else 0):
        th = best[1]
        for z in (-0.8, 0.0, 0.8):
            trial = th.copy()
            trial[prob.i_z[k]] = z
            scored = prob.project(trial)
            if scored[0] < best[0]:
                best = scored
    return best


def _grid_linear(
    prob: Stack, base: np.ndarray, free: np.ndarray, *, quasi_static: bool = False
) -> tuple[float, np.ndarray]:
    """Score a grid of resonance x damping (quasi-static: of the lag, the resonance
    held) by linear projection at a fixed hysteresis shape."""
    nyq = math.pi / prob.dt
    duration = prob.duration
    if quasi_static or not free[IW]:
        wns = [math.exp(base[IW])]
    else:
        wns = np.geomspace(max(2.0 * math.pi * 2.0 / duration, nyq * 1e-3), 10.0 * nyq, 28)
    h_unit = prob.unit_hysteresis(base)
    best = (math.inf, base)
    for wn in wns:
        if not free[ITAU]:
            taus = [math.exp(base[ITAU])]
        elif quasi_static:
            taus = np.geomspace(0.1 * prob.dt, duration / 20.0, 16)
        else:
            taus = [2.0 * zeta / wn for zeta in (0.02, 0.06, 0.2, 0.6, 1.5)]
        for tau in taus:
            th = base.copy()
            th[IW], th[ITAU] = math.log(wn), math.log(tau)
            cost, th = prob.project(th, h_unit)
            if cost < best[0]:
                best = (cost, th)
    return best


def _start(
    records: list[IdentificationData], init: BoucWenParams | None, free: np.ndarray
) -> tuple[np.ndarray, float, float, bool]:
    """Start vector, gain sign, its cost, and whether the start is quasi-static.

    Quasi-static: no record's input has :data:`MIN_BAND_FRACTION` of its power
    above a third of the starting resonance (init's, else a quarter of the
    highest Nyquist frequency), so the records cannot place it; the resonance is
    then held (at init's, else at that Nyquist frequency) and not gridded.
    """
    u = np.concatenate([r.u - np.mean(r.u) for r in records])
    y = np.concatenate([r.y - np.mean(r.y) for r in records])
    coef = np.polyfit(u, y, 1)
    sign = math.copysign(1.0, coef[0]) if init is None else math.copysign(1.0, init.a3)
    dt = min(r.dt for r in records)
    if init is not None:
        base, sign = theta_from_params(init)
    else:
        wn = 0.5 * math.pi / dt
        base = np.zeros(10)
        base[IW] = math.log(wn)
        base[ITAU] = math.log(2.0 * 0.7 / wn)
        u_range = max(r.u.max() for r in records) - min(r.u.min() for r in records)
        base[IB] = math.log(1.0 / float(u_range))
    f_r = math.exp(base[IW]) / (2 * math.pi)
    quasi_static = bool(free[IW] and _band(records, f_r / 3.0, math.inf) < MIN_BAND_FRACTION)
    # the start is scored on the first START_SAMPLES samples of each record (a slow
    # sine's first periods place the loop as well as all of them)
    prob = Stack.build(records, sign, window=START_SAMPLES)
    if init is not None:
        # keep init's values; only the offsets and initial states from the data
        th = prob.expand(base)
        for k in range(prob.n_records):
            scores = []
            for z in (-0.8, 0.0, 0.8):
                trial = th.copy()
                trial[prob.i_z[k]] = z
                scores.append((prob.project(trial)[0], z))
            th[prob.i_z[k]] = min(scores)[1]
        cost, proj = prob.project(th)
        for i in (prob.i_off, prob.i_e1, prob.i_e2):
            th[i] = proj[i]
        return th, sign, cost, quasi_static
    if quasi_static:
        base[IW] = math.log(math.pi / dt)
        base[ITAU] = math.log(2.0 * 0.7 * dt / math.pi)
    th = _grid_hysteresis(prob, prob.expand(base), free)[1]
    th = _grid_linear(prob, th, free, quasi_static=quasi_static)[1]
    cost, th = _grid_hysteresis(prob, th, free)
    return th, sign, cost, quasi_static


def _bounds(start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lo = np.full(start.size, -np.inf)
    hi = np.full(start.size, np.inf)
    for i in (IK, ITAU, IW, IA, IB):
        lo[i], hi[i] = start[i] - 12.0, start[i] + 12.0
    lo[IQ], hi[IQ] = -Q_MAX, Q_MAX
    lo[IZ::4], hi[IZ::4] = -5.0, 5.0  # each record's h0
    return lo, hi


def _refine(
    prob: Stack, start: np.ndarray, free: np.ndarray, max_nfev: int, step_tol: float = STEP_TOL
):
    return solve(prob, start, free, _bounds(start), max_nfev=max_nfev, step_tol=step_tol)


def _multistart(
    prob: Stack,
    start: np.ndarray,
    free: np.ndarray,
    *,
    multistart: int,
    seed: int,
    max_nfev: int,
    say: Callable[[str], None],
) -> tuple[np.ndarray, Solution, int]:
    """The derived start refined, then seeded perturbations of the optimum refined.

    A perturbation that ends with a lower misfit replaces the optimum (a check
    that the optimum is not a local one; from near it each costs a few steps, and at
    most a quarter of ``max_nfev``).
    """
    rng = np.random.default_rng(seed)
    theta, sol = _refine(prob, start, free, max_nfev)
    total = sol.nfev
    say(f"  start 1/{multistart}: cost {2 * sol.cost:.6g} after {sol.nfev} evaluations")
    scale = np.zeros(theta.size)
    scale[[IK, ITAU, IW, IA, IB]] = 0.3
    scale[IQ] = 0.5
    scale[IZ::4] = 0.3  # each record's h0
    for i in range(1, max(1, multistart)):
        th0 = theta + np.where(free, scale * rng.standard_normal(theta.size), 0.0)
        th0[IQ] = float(np.clip(th0[IQ], -Q_MAX + 0.1, Q_MAX - 0.1))
        # a check for a better basin, not a second fit: a quarter of the budget
        th, sol_i = _refine(prob, th0, free, max(1, max_nfev // 4))
        total += sol_i.nfev
        say(f"  start {i + 1}/{multistart}: cost {2 * sol_i.cost:.6g} after {sol_i.nfev} evals")
        if sol_i.cost < sol.cost * (1 - 1e-9) and (sol_i.status > 0 or sol.status == 0):
            theta, sol = th, sol_i
    return theta, sol, total


def identify(
    data: IdentificationData | Sequence[IdentificationData],
    *,
    validation: IdentificationData | Sequence[IdentificationData] | None = None,
    init: str | BoucWenParams | None = None,
    fixed: Iterable[str] = (),
    multistart: int = 3,
    seed: int = 0,
    max_nfev: int = 200,
    name: str = "identified",
    progress: Callable[[str], None] | None = None,
) -> IdentificationResult:
    """Fit (a1, a2, a3, alpha, beta, gamma) to measured records (output error, exact ZOH model).

    Parameters
    ----------
    data : IdentificationData or sequence of IdentificationData
        Training record(s) (:func:`bwdesign.identify.load_data` or
        :meth:`IdentificationData.from_arrays`); t in s, u in V, y in µm. Several
        records (any amplitudes, frequencies and sample rates) are fitted together:
        one parameter set, a sensor offset and an initial state per record
        (``result.records``); the first record is the reference one (its offset,
        initial state and sample time are the result's top-level ones).
    validation : IdentificationData or sequence of them, optional
        Held-out record(s), any sample rate: the fit percent on them is reported
        (each one's offset and initial state re-estimated with the parameters held).
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
    records = _records(data, "data")
    valids = _records(validation, "validation") if validation is not None else []
    multistart = integer(multistart, "multistart", within=MULTISTART)
    tic = time.perf_counter()
    prior = _resolve_init(init)
    say(
        "identify: "
        + "; ".join(f"{r.n} samples at dt = {r.dt:.6g} s" for r in records)
        + "; deriving a start from the data"
    )
    start, sign, cost0, quasi_static = _start(records, prior, _free_mask(fixed, prior))
    say(
        f"  start cost {cost0:.6g}"
        + (
            "; quasi-static first (the input has no power near the resonance)"
            if quasi_static
            else ""
        )
    )
    prob = Stack.build(records, sign)
    free = prob.expand(_free_mask(fixed, prior))
    fit_free = free.copy()
    fit_free[IW] = free[IW] and not quasi_static
    theta, sol, nfev = _multistart(
        prob, start, fit_free, multistart=multistart, seed=seed, max_nfev=max_nfev, say=say
    )
    fit = _Fit(prob, theta, sol, fit_free, nfev)
    if free[IW] and not fit_free[IW] and _resonance_matters(fit, say):
        # the record does see the dynamics: free the resonance (before any delay,
        # which could otherwise stand in for the resonance's phase lag)
        _free_resonance(fit, records, free, max_nfev)
    delay = _search_delay(fit, records, max_nfev, say)
    resonance_held, alternatives = None, []
    if free[IW] and not fit.free[IW]:
        resonance_held = _hold_quasi_static(fit, records, prior, max_nfev, say)
        alternatives = _profile(fit, max_nfev, say)
    elif free[IW]:
        resonance_held, alternatives = _resonance(fit, records, prior, max_nfev, say)
    extensions, delay = _extend(fit, records, valids, delay, max_nfev, say)
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
    result = build_result(fit.prob, outcome, data=records, validation=valids, name=name)
    return replace(
        _with_unexplained(result, fit.theta, records, valids, delay, extensions),
        seconds=time.perf_counter() - tic,
    )


def _with_unexplained(result, theta, records, valids, delay, extensions):
    """``result`` with the extensions document, the disturbance bound and the coverage."""
    bound, coverage, details = unexplained(
        result, theta, records, valids, delay, extensions=extensions
    )
    note = coverage_note(coverage, details)
    if note:
        result = replace(result, diagnostics=(*result.diagnostics, note))
    if valids and not extensions["chosen"]:
        # the base model is the fit: its held-out fit is the validation fit
        extensions["base"]["fit_heldout"] = result.fit_percent["validation"]
        extensions["final"]["fit_heldout"] = result.fit_percent["validation"]
    return replace(
        result, extensions=extensions, disturbance=bound, coverage=coverage, unexplained=details
    )


def _extend(
    fit: _Fit, records: list, valids: list, delay: int, max_nfev: int, say
) -> tuple[dict[str, Any], int]:
    """Model extensions the records need (:mod:`bwdesign.identify.extend`), from the base
    optimum; ``fit`` moves to the chosen model. Returns the extensions document and the
    input delay of the chosen model."""
    ctx = make_context(
        records=records,
        valids=valids,
        delay=delay,
        free=fit.free,
        refine=_refine,
        max_nfev=max_nfev,
        creep_taus=tuple(t for t in CREEP_TAUS if t <= fit.prob.duration),
    )
    model, extensions = select_extensions(fit.prob, fit.theta, fit.sol, ctx, say)
    fit.nfev += ctx.nfev
    fit.prob, fit.theta, fit.sol = model.prob, model.theta, model.sol
    return extensions, model.delay


def _records(data: Any, what: str) -> list[IdentificationData]:
    """One record or a non-empty sequence of them, as a list."""
    if isinstance(data, IdentificationData):
        return [data]
    items = list(data) if isinstance(data, list | tuple) else None
    if not items or not all(isinstance(r, IdentificationData) for r in items):
        raise InputError(
            f"{what} must be an IdentificationData or a non-empty list of them (use "
            "bwdesign.identify.load_data)"
        )
    return items


@dataclass
class _Fit:
    """The search so far: the problem (input delay), the optimum, what is free, the cost."""

    prob: Stack
    theta: np.ndarray
    sol: Any
    free: np.ndarray
    nfev: int


def _search_delay(fit: _Fit, records: list[IdentificationData], max_nfev: int, say) -> int:
    """The input delay (samples, the same for every record) that earns its place; ``fit``
    moves to it."""
    delay = 0
    for d in _DELAYS[1:]:
        # a delay must earn its place: a likelihood-ratio gain above chi2(1, 0.999)
        trial = Stack.build(records, fit.prob.sign, delay=d)
        th_d, sol_d = _refine(trial, fit.theta, fit.free, max_nfev)
        fit.nfev += sol_d.nfev
        if not trial.n * math.log(fit.sol.cost / max(sol_d.cost, 1e-300)) > _LR_DELAY:
            break
        say(f"  input delay {d} sample(s): cost {2 * sol_d.cost:.6g}")
        delay, fit.theta, fit.sol, fit.prob = d, th_d, sol_d, trial
    return delay


def _free_resonance(fit: _Fit, records: list[IdentificationData], free: np.ndarray, max_nfev: int):
    """Refit with the resonance free: from the quasi-static optimum and from a grid
    over resonance and damping at its hysteresis shape; the lower misfit wins."""
    window = Stack.build(records, fit.prob.sign, window=START_SAMPLES)
    th = _grid_linear(window, fit.theta, free)[1]
    th = _grid_hysteresis(window, th, free)[1]
    best = None
    for th0 in (fit.theta, th):
        th_k, sol_k = _refine(fit.prob, th0, free, max_nfev)
        fit.nfev += sol_k.nfev
        if best is None or (sol_k.status > 0, -sol_k.cost) > (best[1].status > 0, -best[1].cost):
            best = (th_k, sol_k)
    fit.free = free.copy()
    fit.theta, fit.sol = best


def _resonance_matters(fit: _Fit, say) -> bool:
    """Score test at the quasi-static optimum: would a free resonance lower the misfit?

    The Gauss-Newton decrease from freeing it, in noise variances, against
    chi-square(1, 0.999) (the threshold a delay must also pass).
    """
    free = fit.free.copy()
    free[IW] = True
    free[fit.prob.i_off] = False
    r = fit.prob.centre(fit.prob.residual(fit.theta))
    jac = fit.prob.centre(fit.prob.jacobian(fit.theta, free))
    u, s, _ = np.linalg.svd(jac, full_matrices=False)
    ok = s > s[0] * 1e-10
    decrease = float(np.sum((u[:, ok].T @ r) ** 2))
    s2 = float(r @ r) / max(1, r.size - int(free.sum()) - fit.prob.n_records)
    stat = decrease / s2
    say(f"  score test for a free resonance: {stat:.3g} noise variances (threshold {_LR_DELAY:g})")
    return stat > _LR_DELAY


def _hold_quasi_static(
    fit: _Fit, records: list[IdentificationData], prior: BoucWenParams | None, max_nfev: int, say
) -> tuple[str, float, float, float]:
    """Hold the resonance of a quasi-static fit at init's or the stated default."""
    theta = fit.theta
    if prior is not None:
        src, wn_hold = "init", math.sqrt(prior.a1)
    else:
        src, wn_hold = "default", max(math.pi / fit.prob.dt, 2.0 / math.exp(theta[ITAU]))
    if abs(math.log(wn_hold) - theta[IW]) > 1e-12:
        theta = theta.copy()
        theta[IW] = math.log(wn_hold)
        fit.theta, fit.sol = _refine(fit.prob, theta, fit.free, max_nfev)
        fit.nfev += fit.sol.nfev
    cov_free = fit.free.copy()
    cov_free[IW] = True
    rel = _rel_halfwidth(fit.prob, fit.theta, cov_free, IW)
    f_r = wn_hold / (2 * math.pi)
    band = _band(records, f_r / 3.0, 3.0 * f_r)
    say(
        f"  the resonance is not determined by these data (input power within a factor 3 "
        f"of {f_r:.4g} Hz: {band:.3g} of the total); holding it there"
    )
    return src, wn_hold, rel, band


def _resonance(
    fit: _Fit, records: list[IdentificationData], prior: BoucWenParams | None, max_nfev: int, say
) -> tuple[tuple[str, float, float, float] | None, list[np.ndarray]]:
    """Whether the record determines a freely fitted resonance; if not, hold and profile it.

    Returns ``(resonance_held, alternatives)``: ``(source, wn, rel, band)`` of a held
    resonance (``fit`` refitted with it held unless the record's own curvature placed
    it) and the other resonances that fit the record as well (they widen the intervals).
    """
    theta, prob = fit.theta, fit.prob
    rel = _rel_halfwidth(prob, theta, fit.free, IW)
    f_r = math.exp(theta[IW]) / (2 * math.pi)
    band = _band(records, f_r / 3.0, 3.0 * f_r)
    say(f"  resonance {f_r:.4g} Hz: input power within [f/3, 3f]: {band:.3g} of the total")
    if rel < DETERMINED_REL and band >= MIN_BAND_FRACTION:
        return None, []
    tau = math.exp(theta[ITAU])
    if prior is not None:
        src, wn_hold = "init", math.sqrt(prior.a1)
    elif rel < DETERMINED_REL and f_r < 0.5 / prob.dt:
        # the low-frequency curvature placed it inside the record's band: a
        # guess worth keeping, but not a determination
        src, wn_hold = "curvature", math.exp(theta[IW])
    else:
        src, wn_hold = "default", max(math.pi / prob.dt, 2.0 / tau)
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
    return (src, wn_hold, rel, band), _profile(fit, max_nfev, say)


def _profile(fit: _Fit, max_nfev: int, say) -> list[np.ndarray]:
    """Other resonances that fit the record as well (they widen the intervals)."""
    alternatives: list[np.ndarray] = []
    held = fit.free.copy()
    held[IW] = False
    s2 = 2.0 * fit.sol.cost / max(1, fit.prob.n - int(held.sum()))
    for factor in _PROFILE_FACTORS:
        th_k = fit.theta.copy()
        th_k[IW] += math.log(factor)
        th_k, sol_k = solve(fit.prob, th_k, held, _bounds(th_k), max_nfev=max_nfev, step_tol=0.3)
        fit.nfev += sol_k.nfev
        if 2.0 * (sol_k.cost - fit.sol.cost) <= _CHI2_95 * s2:
            alternatives.append(th_k)
    say(f"  {len(alternatives)} other resonance(s) fit as well: intervals widened")
    return alternatives


def _band(records: list[IdentificationData], f_lo: float, f_hi: float) -> float:
    """The largest share of a record's input power within ``[f_lo, f_hi]`` Hz."""
    return max(_band_fraction(r.u, r.dt, f_lo, f_hi) for r in records)


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


def _rel_halfwidth(prob: Stack, theta: np.ndarray, free: np.ndarray, index: int) -> float:
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
