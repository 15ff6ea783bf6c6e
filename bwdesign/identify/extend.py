"""Choosing model extensions after the base fit: only those the data need.

Candidates (:mod:`bwdesign.identify.extstack`): an amplifier first-order lag,
creep (a bank of first-order lags, :data:`~bwdesign.identify.extstack.CREEP_TAUS`
up to the longest record's length), a sensor drift per record. Forward selection
from the base optimum:

1. **Screen** every remaining candidate at the current optimum: the Gauss-Newton
   misfit decrease from adding its columns (creep, drift: exact columns; amplifier
   lag: the output change of a one-sample lag) beside the model's own Jacobian, as
   a predicted BIC change. A candidate whose columns lie within the model's own
   (less than :data:`SEPARABLE` of their norm outside) is *not determined*.
2. **Fit** the best-screened one (the amplifier lag profiled over a grid of time
   constants scored by short refits, by full ones when the best is at an end of
   the grid, then polished to :data:`LAG_RTOL`; creep weights and drifts in closed
   form) from the current optimum.
3. **Choose** it only when both say so: the BIC on the output error with the
   effective sample count, ``BIC = n_eff ln(RSS/n) + k ln(n_eff)``,
   ``n_eff = n (1 - rho1)/(1 + rho1)`` from the current residual's lag-1
   autocorrelation ``rho1`` (the residuals are coloured: an AR(1) count), is
   lower, AND the held-out fit is higher by at least :data:`MIN_HELDOUT_GAIN`
   percentage points (a practical threshold: what a smaller gain would explain is
   left to the disturbance bound, :mod:`bwdesign.identify.unexplained`). The
   screen already drops a candidate whose predicted BIC change is not positive or
   whose one-step training-fit gain is below that threshold. Held out: the
   validation record(s) when given (each one's offset and initial state
   re-estimated), else the last :data:`HOLDOUT` of every training record (the
   current and the extended model refitted on the first part, simulated on
   through the rest). The amplifier lag is also tried without the base fit's
   input delay (which may have stood in for it).

4. **Together**, when the residual is still coloured (lag-1 autocorrelation above
   :data:`COLOURED`): every determined candidate fitted at once (the amplifier lag
   on a grid of full refits), then each kept only if the rest without it is worse
   by the same two tests (:func:`_joint`).

The base model's fit is the start of every step, so records the base model
explains (nothing passes the screen) pay one Jacobian per candidate.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from types import SimpleNamespace
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from .extstack import CREEP_TAUS, ExtConfig, ExtStack
from .problem import Problem
from .result import pooled_fit, residual_whiteness, validate_record
from .stack import Stack

__all__ = ["select_extensions", "HOLDOUT", "MIN_HELDOUT_GAIN", "SEPARABLE", "effective_n"]

#: Share of each training record held out when no validation record is given.
HOLDOUT = 0.25
#: Least held-out fit gain (percentage points) for an extension to be chosen.
MIN_HELDOUT_GAIN = 0.05
#: Least share of a candidate's column norm outside the model's own columns.
SEPARABLE = 1e-3
_CANDIDATES = ("amplifier_lag", "creep", "drift")
#: Lag-1 autocorrelation of the residual above which every determined candidate is fitted.
COLOURED = 0.9
#: Relative accuracy of the fitted amplifier lag (its log).
LAG_RTOL = 2e-4
#: Largest amplifier lag tried (s).
_AMP_MAX = 0.05

Refine = Callable[..., tuple[np.ndarray, Any]]


def effective_n(r: np.ndarray) -> float:
    """``n (1 - rho1)/(1 + rho1)`` of a residual (``rho1`` its lag-1 autocorrelation >= 0)."""
    rho = min(max(residual_whiteness(r - np.mean(r))[0], 0.0), 0.999)
    return max(2.0, r.size * (1.0 - rho) / (1.0 + rho))


@dataclass
class _Model:
    cfg: ExtConfig
    prob: Stack
    theta: np.ndarray
    sol: Any
    delay: int


def _build(records, sign, cfg: ExtConfig, delay: int) -> Stack:
    if not cfg.names:
        return Stack.build(records, sign, delay=delay)
    return ExtStack.build_ext(records, sign, cfg, delay=delay)


def _add(cfg: ExtConfig, name: str, creep_taus: tuple[float, ...], amp_tau: float) -> ExtConfig:
    if name == "amplifier_lag":
        return replace(cfg, amp_tau=amp_tau)
    if name == "creep":
        return replace(cfg, creep_taus=creep_taus)
    return replace(cfg, drift=True)


def _remove(cfg: ExtConfig, name: str) -> ExtConfig:
    if name == "amplifier_lag":
        return replace(cfg, amp_tau=0.0)
    if name == "creep":
        return replace(cfg, creep_taus=())
    return replace(cfg, drift=False)


def _k(cfg: ExtConfig, n_records: int) -> int:
    return cfg.n_extra + (n_records if cfg.drift else 0)


def _rss(m: _Model) -> float:
    return 2.0 * float(m.sol.cost)


@dataclass
class _Ctx:
    records: list
    valids: list
    delay: int
    free: np.ndarray
    refine: Refine
    max_nfev: int
    creep_taus: tuple[float, ...]
    nfev: int = 0


def _summary(m: _Model, ctx: _Ctx, heldout: float | None) -> dict[str, Any]:
    r = m.prob.centre(m.prob.residual(m.theta))
    acf1, frac = residual_whiteness(r)
    ys = [p.y for p in m.prob.problems]
    return {
        "fit_train": pooled_fit(ys, m.prob.predict_each(m.theta)),
        "fit_heldout": heldout,
        "acf1": acf1,
        "frac_out": frac,
        "n_params": _k(m.cfg, m.prob.n_records),
    }


def _at_optimum(m: _Model, ctx: _Ctx) -> tuple[np.ndarray, np.ndarray]:
    """The centred residual at ``m``'s optimum and an orthonormal basis of its centred
    Jacobian's columns (offsets excluded: they are projected out already)."""
    prob = m.prob
    free = ctx.free.copy()
    free[prob.i_off] = False
    jac = prob.centre(prob.jacobian(m.theta, free))
    u, sv, _ = np.linalg.svd(jac, full_matrices=False)
    keep = sv > sv[0] * 1e-10 if sv.size and sv[0] > 0 else np.zeros(sv.size, dtype=bool)
    return prob.centre(prob.residual(m.theta)), u[:, keep]


def _screen(
    m: _Model, name: str, ctx: _Ctx, at: tuple[np.ndarray, np.ndarray]
) -> tuple[float, str, dict[str, Any]]:
    """Predicted BIC change of adding ``name`` at ``m``'s optimum, a reason when it cannot
    be determined, and the fit/whiteness after one Gauss-Newton step with it."""
    prob = m.prob
    r, qj = at
    base = np.concatenate([p.residual(prob.local(m.theta, k)) for k, p in enumerate(prob.problems)])
    if name == "amplifier_lag":
        tau = 2.0 * prob.dt
        trial = _build(ctx.records, prob.sign, replace(m.cfg, amp_tau=tau), m.delay)
        lagged = np.concatenate(
            [p.residual(trial.local(m.theta, k)) for k, p in enumerate(trial.problems)]
        )
        cols = (lagged - base)[:, None]
    else:
        extra = ExtStack.build_ext(
            ctx.records, prob.sign, _add(ExtConfig(), name, ctx.creep_taus, 0.0), delay=m.delay
        )
        cols = extra.basis[:, extra.n_records :]
    x = prob.centre(cols)
    x_perp = x - qj @ (qj.T @ x)
    share = float(np.linalg.norm(x_perp) / max(np.linalg.norm(x), 1e-300))
    q = np.linalg.qr(x_perp)[0]
    step = q @ (q.T @ r)
    rss0 = float(r @ r)
    dec = float(step @ step)
    n_eff = effective_n(r)
    k = cols.shape[1] if name != "amplifier_lag" else 1
    dbic = -n_eff * math.log(max(1.0 - dec / rss0, 1e-300)) - k * math.log(n_eff)
    r1 = r - step
    ys = [p.y for p in prob.problems]
    models = [y + prob.y_scale * r1[b] for y, b in zip(ys, prob.blocks(), strict=True)]
    acf1, frac = residual_whiteness(r1)
    row = {"fit_train": pooled_fit(ys, models), "fit_heldout": None, "acf1": acf1}
    row["frac_out"] = frac
    row["separable"] = share
    reason = ""
    if share < SEPARABLE:
        reason = (
            f"not determined: only {share:.2g} of its effect lies outside what the base "
            "model's own parameters already do on this record"
        )
    return dbic, reason, row


def _screen_reason(
    dbic: float, reason: str, row: dict[str, Any], fit_now: float, stand_in: bool = False
) -> str:
    """Why a screened candidate is not fitted ("" when it is). ``stand_in``: an input
    delay may be standing in for it (the amplifier lag), so the one-step gain, taken
    with the delay in place, does not count."""
    if reason:
        return reason
    if dbic <= 0.0:
        return f"not needed: the predicted BIC change is {dbic:.3g} (<= 0)"
    gain = row["fit_train"] - fit_now
    if gain < MIN_HELDOUT_GAIN and not stand_in:
        return (
            f"not needed: it would raise the training fit by {gain:.3g} points (one "
            f"Gauss-Newton step), below the {MIN_HELDOUT_GAIN:g} points asked of the "
            "held-out fit; what it would explain stays in the disturbance bound"
        )
    return ""


def _fit_candidate(m: _Model, name: str, ctx: _Ctx) -> tuple[_Model, str]:
    """``m`` with ``name`` added, refitted from ``m``'s optimum (amplifier lag: profiled)."""
    if name != "amplifier_lag":
        cfg = _add(m.cfg, name, ctx.creep_taus, 0.0)
        prob = _build(ctx.records, m.prob.sign, cfg, m.delay)
        th, sol = ctx.refine(prob, m.theta, ctx.free, ctx.max_nfev)
        ctx.nfev += sol.nfev
        return _Model(cfg, prob, th, sol, m.delay), ""
    # an input delay found by the base fit may have stood in for the lag: the lag is
    # profiled without it as well, and the delay of the lower misfit on the grid is kept
    delay, scored = _best_lag_grid(m, ctx)
    best = min(range(len(scored)), key=lambda j: scored[j][0])
    if best in (0, len(scored) - 1):
        # at an end of the range: the short refits may have stopped short; full ones decide
        delay, scored = _best_lag_grid(m, ctx, full=True)
    return _profile_lag(m, delay, scored, ctx)


def _best_lag_grid(m: _Model, ctx: _Ctx, *, full: bool = False) -> tuple[int, list]:
    """:func:`_lag_grid` with and without ``m``'s input delay: the one of lower misfit."""
    grids = [_lag_grid(m, delay, ctx, full=full) for delay in sorted({0, m.delay})]
    return min(grids, key=lambda g: min(c for c, _, _ in g[1]))


def _lag_grid(m: _Model, delay: int, ctx: _Ctx, *, full: bool = False) -> tuple[int, list]:
    """The misfit over amplifier lags from one sample to :data:`_AMP_MAX` (octaves);
    each lag scored by a short refit (``full``: a complete one)."""
    dt = m.prob.dt
    grid = [dt * f for f in (1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0) if dt * f <= _AMP_MAX]
    scored = []
    for tau in grid:
        prob = _build(ctx.records, m.prob.sign, replace(m.cfg, amp_tau=tau), delay)
        if full:
            th, sol = ctx.refine(prob, m.theta, ctx.free, ctx.max_nfev)
        else:
            th, sol = ctx.refine(prob, m.theta, ctx.free, 30, step_tol=0.3)
        ctx.nfev += sol.nfev
        scored.append((sol.cost, tau, th))
    return delay, scored


def _profile_lag(m: _Model, delay: int, scored: list, ctx: _Ctx) -> tuple[_Model, str]:
    """The grid's best amplifier lag refined (bounded Brent search in log tau between
    its neighbours), then refitted there."""
    grid = [tau for _, tau, _ in scored]
    i = min(range(len(scored)), key=lambda j: scored[j][0])
    tau, start, note = scored[i][1], scored[i][2], ""
    if 0 < i < len(scored) - 1:
        # the misfit profiled in log tau between the best grid point's neighbours
        cache: dict[float, tuple[float, np.ndarray]] = {}

        def cost(x: float) -> float:
            prob = _build(ctx.records, m.prob.sign, replace(m.cfg, amp_tau=math.exp(x)), delay)
            th, sol = ctx.refine(prob, start, ctx.free, 30, step_tol=0.3)
            ctx.nfev += sol.nfev
            cache[x] = (sol.cost, th)
            return sol.cost

        lo, hi = math.log(scored[i - 1][1]), math.log(scored[i + 1][1])
        best = minimize_scalar(
            cost, bounds=(lo, hi), method="bounded", options={"xatol": 0.05, "maxiter": 8}
        )
        if cache and min(cache.values(), key=lambda v: v[0])[0] < scored[i][0]:
            x_best = min(cache, key=lambda x: cache[x][0])
            tau, start = math.exp(x_best), cache[x_best][1]
        del best
    else:
        note = (
            f"not determined: the best amplifier lag is at the end of the range tried "
            f"({1e3 * grid[0]:.3g} to {1e3 * grid[-1]:.3g} ms)"
        )
    if note:
        cfg = replace(m.cfg, amp_tau=tau)
        prob = _build(ctx.records, m.prob.sign, cfg, delay)
        th, sol = ctx.refine(prob, start, ctx.free, ctx.max_nfev)
        ctx.nfev += sol.nfev
        return _Model(cfg, prob, th, sol, delay), note
    return _polish_lag(m, delay, tau, start, ctx), note


def _polish_lag(m: _Model, delay: int, tau: float, start: np.ndarray, ctx: _Ctx) -> _Model:
    """The lag at the minimum of the fully refitted misfit, to :data:`LAG_RTOL`.

    The grid and the Brent search score each lag with a short, coarse refit; the lag
    is held while the rest is fitted, so an error of a few per cent in it moves the
    other parameters (a 2 % lag error moved the resonance's a1 by 1 % and gamma by
    19 % on a generated record). Parabolic steps in ``log tau`` through three full
    refits, a handful of iterations.
    """
    fits: dict[float, _Model] = {}

    def model(x: float, th0: np.ndarray) -> _Model:
        x = round(x, 12)
        if x not in fits:
            cfg = replace(m.cfg, amp_tau=math.exp(x))
            prob = _build(ctx.records, m.prob.sign, cfg, delay)
            th, sol = ctx.refine(prob, th0, ctx.free, ctx.max_nfev)
            ctx.nfev += sol.nfev
            fits[x] = _Model(cfg, prob, th, sol, delay)
        return fits[x]

    x, h = math.log(tau), 0.04
    best = model(x, start)
    for _ in range(6):
        lo, hi = model(x - h, best.theta), model(x + h, best.theta)
        c0, cl, ch = best.sol.cost, lo.sol.cost, hi.sol.cost
        curv = (cl + ch - 2.0 * c0) / (h * h)
        slope = (ch - cl) / (2.0 * h)
        step = -slope / curv if curv > 0 else math.copysign(2.0 * h, -slope)
        step = float(np.clip(step, -2.0 * h, 2.0 * h))
        trial = model(x + step, best.theta)
        cands = [(c0, x, best), (cl, x - h, lo), (ch, x + h, hi), (trial.sol.cost, x + step, trial)]
        _, x_new, best = min(cands, key=lambda c: c[0])
        if abs(x_new - x) < LAG_RTOL and h <= 4 * LAG_RTOL:
            break
        x, h = x_new, max(min(h, 2.0 * abs(x_new - x)), LAG_RTOL)
    return best


def _window(rec, stop: int):
    return SimpleNamespace(t=rec.t[:stop], u=rec.u[:stop], y=rec.y[:stop], dt=rec.dt)


def _heldout(m: _Model, ctx: _Ctx) -> float:
    """Held-out fit (%) of ``m`` (see the module docstring)."""
    if ctx.valids:
        ys, models = [], []
        for rec in ctx.valids:
            u_in, known = m.prob.validation_inputs(rec, m.delay, m.theta)
            vprob = Problem(u_in, rec.y - known, rec.dt, m.prob.sign)
            ys.append(rec.y)
            models.append(validate_record(vprob, m.prob.local(m.theta, 0))[0] + known)
        return pooled_fit(ys, models)
    stops = [int(round((1.0 - HOLDOUT) * r.y.size)) for r in ctx.records]
    part = [_window(r, s) for r, s in zip(ctx.records, stops, strict=True)]
    win = _build(part, m.prob.sign, m.cfg, m.delay)
    th, sol = ctx.refine(win, m.theta, ctx.free, ctx.max_nfev)
    ctx.nfev += sol.nfev
    full = _build(ctx.records, m.prob.sign, m.cfg, m.delay)
    # the window's output scale and means, so that th means the same on the full record
    full.y_scale = win.y_scale
    for pf, pw in zip(full.problems, win.problems, strict=True):
        pf.y_mean, pf.y_scale = pw.y_mean, pw.y_scale
    preds = Stack.predict_each(full, th)
    if isinstance(full, ExtStack):
        extra = np.zeros(full.n)
        coef = win.coefficients(th)
        r_n = full.n_records
        extra = full.y_scale * (full.basis[:, r_n:] @ coef[r_n:])
        preds = [p + extra[b] for p, b in zip(preds, full.blocks(), strict=True)]
    ys = [r.y[s:] for r, s in zip(ctx.records, stops, strict=True)]
    return pooled_fit(ys, [p[s:] for p, s in zip(preds, stops, strict=True)])


def select_extensions(
    prob: Stack,
    theta: np.ndarray,
    sol: Any,
    ctx: _Ctx,
    say: Callable[[str], None],
) -> tuple[_Model, dict[str, Any]]:
    """Forward selection of the extensions (module docstring); the chosen model and
    the ``extensions`` document of the result."""
    cur = _Model(ExtConfig(), prob, theta, sol, ctx.delay)
    held: dict[tuple[str, ...], float] = {}
    base_row = _summary(cur, ctx, None)
    rows: dict[str, dict[str, Any]] = {}
    remaining = list(_CANDIDATES)
    if not ctx.creep_taus:
        remaining.remove("creep")
        rows["creep"] = {
            "chosen": False,
            "reason": f"not determined: the records are shorter than {CREEP_TAUS[0]:g} s",
        }
    while remaining:
        at = _at_optimum(cur, ctx)
        screened = {name: _screen(cur, name, ctx, at) for name in remaining}
        order = sorted(remaining, key=lambda nm: -screened[nm][0])
        name = order[0]
        fit_now = (
            base_row["fit_train"] if not cur.cfg.names else _summary(cur, ctx, None)["fit_train"]
        )
        why_not = {
            nm: _screen_reason(*screened[nm], fit_now, nm == "amplifier_lag" and cur.delay > 0)
            for nm in remaining
        }
        order = [nm for nm in order if not why_not[nm]] + [nm for nm in order if why_not[nm]]
        name = order[0]
        if why_not[name]:
            for nm in order:
                d, _, r_nm = screened[nm]
                rows[nm] = r_nm | {"chosen": False, "delta_bic": d, "reason": why_not[nm]}
            break
        trial, note = _fit_candidate(cur, name, ctx)
        dbic, n_eff = _delta_bic(cur, trial)
        h_trial = _heldout(trial, ctx)
        if cur.cfg.names not in held:
            held[cur.cfg.names] = _heldout(cur, ctx)
            if not cur.cfg.names:
                base_row["fit_heldout"] = held[()]
        h_cur = held[cur.cfg.names]
        gain = h_trial - h_cur
        chosen = not note and dbic > 0.0 and gain >= MIN_HELDOUT_GAIN
        why = note or (
            f"BIC change {dbic:.4g} with n_eff {n_eff:.0f}, held-out fit {gain:+.3g} points"
        )
        rows[name] = (
            _summary(trial, ctx, h_trial)
            | {
                "chosen": chosen,
                "delta_bic": dbic,
                "reason": ("chosen: " if chosen else "not chosen: ") + why,
            }
            | _values(trial, name)
        )
        say(f"  extension {name}: {rows[name]['reason']}")
        remaining.remove(name)
        if chosen:
            cur = trial
            held[cur.cfg.names] = h_trial
    if _summary(cur, ctx, None)["acf1"] > COLOURED:
        cur = _joint(cur, rows, held, ctx, say)
    for nm in cur.cfg.names:  # the values of the model chosen, not of the step that chose it
        rows[nm] = rows[nm] | _values(cur, nm)
    doc = {
        "chosen": list(cur.cfg.names),
        "criterion": (
            "forward selection from the base fit; chosen when BIC on the output error with "
            "n_eff = n (1 - rho1)/(1 + rho1) is lower AND the held-out fit is higher by >= "
            f"{MIN_HELDOUT_GAIN:g} points; held out: "
            + (
                "the validation record(s)"
                if ctx.valids
                else f"the last {100 * HOLDOUT:g} % of each training record"
            )
        ),
        "base": base_row,
        "final": _summary(cur, ctx, held.get(cur.cfg.names)),
        "candidates": rows,
    }
    return cur, doc


def _delta_bic(cur: _Model, trial: _Model) -> tuple[float, float]:
    """BIC change from ``cur`` to ``trial`` on the output error, and the ``n_eff`` used
    (from ``cur``'s residual)."""
    n_eff = effective_n(cur.prob.centre(cur.prob.residual(cur.theta)))
    r_n = cur.prob.n_records
    dk = _k(trial.cfg, r_n) - _k(cur.cfg, r_n)
    return n_eff * math.log(_rss(cur) / max(_rss(trial), 1e-300)) - dk * math.log(n_eff), n_eff


def _criteria(cur: _Model, trial: _Model, held: dict, ctx: _Ctx) -> tuple[float, float]:
    """BIC change (``n_eff`` from ``cur``'s residual) and held-out fit gain of ``trial``."""
    dbic = _delta_bic(cur, trial)[0]
    for m in (cur, trial):
        if m.cfg.names not in held:
            held[m.cfg.names] = _heldout(m, ctx)
    return dbic, held[trial.cfg.names] - held[cur.cfg.names]


def _joint(cur: _Model, rows: dict, held: dict, ctx: _Ctx, say) -> _Model:
    """Every determined candidate fitted together, then each dropped that is not needed.

    Used when the residual stays coloured (lag-1 autocorrelation above
    :data:`COLOURED`) after forward selection: a slow behaviour the model lacks
    can pull the base optimum far from the stage (an input delay standing in for an
    amplifier lag, the hysteresis flattened to follow creep), and from there no single
    extension lowers the misfit while all of them together do. Chosen on the same
    criteria as one at a time, against the model selection ended with.
    """
    names = [
        nm
        for nm in _CANDIDATES
        if nm not in cur.cfg.names
        and not str(rows.get(nm, {}).get("reason", "")).startswith("not determined")
    ]
    if len(names) < 2:
        return cur
    m = cur
    linear = [nm for nm in names if nm != "amplifier_lag"]
    if linear:
        cfg = cur.cfg
        for nm in linear:
            cfg = _add(cfg, nm, ctx.creep_taus, 0.0)
        prob = _build(ctx.records, cur.prob.sign, cfg, cur.delay)
        th, sol = ctx.refine(prob, cur.theta, ctx.free, ctx.max_nfev)
        ctx.nfev += sol.nfev
        m = _Model(cfg, prob, th, sol, cur.delay)
    if "amplifier_lag" in names:
        # from a biased optimum the short refits of the grid do not leave it: full ones
        delay, scored = _best_lag_grid(m, ctx, full=True)
        lagged, note = _profile_lag(m, delay, scored, ctx)
        if note:  # not determined together either: the others without it
            names.remove("amplifier_lag")
        else:
            m = lagged
    if m is cur:
        return cur
    dbic, gain = _criteria(cur, m, held, ctx)
    if not (dbic > 0.0 and gain >= MIN_HELDOUT_GAIN):
        say(f"  extensions together ({', '.join(names)}): not chosen")
        return cur
    # each one dropped in turn: kept only if the rest without it is worse by the criteria
    for nm in names:
        reduced_cfg = _remove(m.cfg, nm)
        prob = _build(ctx.records, m.prob.sign, reduced_cfg, m.delay)
        th, sol = ctx.refine(prob, m.theta, ctx.free, ctx.max_nfev)
        ctx.nfev += sol.nfev
        reduced = _Model(reduced_cfg, prob, th, sol, m.delay)
        d_keep, g_keep = _criteria(reduced, m, held, ctx)
        keep = d_keep > 0.0 and g_keep >= MIN_HELDOUT_GAIN
        why = (
            f"together with the others, after one at a time stayed at the base model's "
            f"optimum (residual lag-1 autocorrelation above {COLOURED:g}): BIC change "
            f"{d_keep:.4g}, held-out fit {g_keep:+.3g} points against the rest without it"
        )
        rows[nm] = (
            _summary(m, ctx, held[m.cfg.names])
            | {
                "chosen": keep,
                "delta_bic": d_keep,
                "reason": ("chosen " if keep else "not chosen: ") + why,
            }
            | _values(m, nm)
        )
        say(f"  extension {nm}: {rows[nm]['reason']}")
        if not keep:
            m = reduced
    return m


def _values(m: _Model, name: str) -> dict[str, Any]:
    if name == "amplifier_lag":
        return {"tau_s": m.cfg.amp_tau, "delay_samples": m.delay}
    if name == "creep" and isinstance(m.prob, ExtStack):
        return {"taus_s": list(m.cfg.creep_taus), "weights": list(m.prob.creep_weights(m.theta))}
    if name == "drift" and isinstance(m.prob, ExtStack):
        c = m.prob.coefficients(m.theta)
        r_n = m.prob.n_records
        k = len(m.cfg.creep_taus)
        return {"slopes_per_s": [float(m.prob.y_scale * v) for v in c[r_n + k :]]}
    return {}


def make_context(**kw: Any) -> _Ctx:
    """The selection's inputs: records, valids, delay, free, refine, max_nfev, creep_taus."""
    return _Ctx(**kw)
