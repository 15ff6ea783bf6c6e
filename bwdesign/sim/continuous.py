"""The continuous-time closed loop (:func:`simulate_continuous`); see :mod:`bwdesign.sim`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..control.loop import ClosedLoop
from ..errors import InputError
from ..model.params import BoucWenParams
from ..model.plant import hysteresis_increment
from ..model.references import Reference, Triangle
from ..validate import DT, Range, real
from .result import SimulationResult
from .run import Run, finish, prepare

__all__ = ["simulate_continuous", "ContinuousSolver"]

#: Supported tolerances of the stiff solver.
_TOL = Range(1e-14, 1e-1, unit="")
_POSITIVE = Range(0.0, math.inf, lo_open=True)


@dataclass(frozen=True)
class ContinuousSolver:
    """How :func:`simulate_continuous` integrates.

    Parameters
    ----------
    method : {"Radau", "BDF", "LSODA"}
        ``solve_ivp`` stiff method.
    rtol : float
    atol : float, optional
        Absolute tolerance; default ``1e-10`` times each state's scale.
    max_step : float, optional
        Largest step (s); default ``output_dt``.
    output_dt : float, optional
        Spacing of the recorded samples (s); default ``min(period, duration)/5000``.
    amplifier_bandwidth : float, optional
        Model the amplifier as ``u' = wc (u_cmd - u)`` (rad/s) instead of solving the
        implicit relation for ``u'``.
    """

    method: str = "Radau"
    rtol: float = 1e-8
    atol: float | None = None
    max_step: float | None = None
    output_dt: float | None = None
    amplifier_bandwidth: float | None = None

    def __post_init__(self) -> None:
        if self.method not in ("Radau", "BDF", "LSODA"):
            raise InputError(
                f"method must be a stiff solver (Radau, BDF, LSODA), got {self.method!r}"
            )
        object.__setattr__(self, "rtol", real(self.rtol, "rtol", within=_TOL))
        for name in ("atol", "max_step", "amplifier_bandwidth"):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, real(v, name, within=_POSITIVE))


# -- continuous-time loop -----------------------------------------------------


def _kappa(p: BoucWenParams, s: float, h: float) -> float:
    return p.alpha - p.beta * s * h - p.gamma * abs(h)


def _solve_udot(A: float, c: float, p: BoucWenParams, h: float) -> float:
    """Solve ``v = A + c kappa(sign v, h) v`` for the input rate ``v`` (V/s)."""
    if A == 0.0:
        return 0.0
    s = 1.0 if A > 0 else -1.0
    den = 1.0 - c * _kappa(p, s, h)
    if den <= 0.0:
        raise InputError(
            f"the implicit relation for u' is ill-posed: (a1/a3) dh/du = "
            f"{c * _kappa(p, s, h):.4g} >= 1 at x3hat = {h:.4g}; use amplifier_bandwidth"
        )
    return A / den


def _scalar_reference(reference: Reference):
    """Return ``t -> (r, r')`` with ``r = (x_d, x_d', x_d'')`` at one time, without arrays."""
    from ..model.references import Sine

    if isinstance(reference, Sine):
        A, off = reference.amplitude, reference.offset
        w, ph = 2 * math.pi * reference.frequency, reference.phase

        def sine(tt: float):
            th = w * tt + ph
            s, c = math.sin(th), math.cos(th)
            r = np.array([off + A * s, A * w * c, -A * w * w * s])
            return r, np.array([r[1], r[2], -A * w**3 * c])

        return sine

    def generic(tt: float):
        xd, vd, ad = reference.evaluate(np.array([tt]))
        jk = reference.jerk(np.array([tt]))
        return np.array([xd[0], vd[0], ad[0]]), np.array([vd[0], ad[0], jk[0]])

    return generic


def _breakpoints(reference: Reference, t_end: float) -> list[float]:
    """Times where ``x_d'`` jumps (sharp triangle corners, sharp steps)."""
    out: list[float] = []
    if isinstance(reference, Triangle) and reference.corner_time == 0:
        f = reference.frequency
        t0 = (-0.5 * math.pi - reference.phase) / (2 * math.pi * f)
        half = 0.5 / f
        k0 = math.ceil((0.0 - t0) / half)
        tb = t0 + k0 * half
        while tb < t_end:
            if tb > 0:
                out.append(tb)
            tb += half
    t_step = getattr(reference, "t_step", None)
    if reference.kind == "step" and 0 < t_step < t_end:
        out.append(float(t_step))
    return sorted(out)


def simulate_continuous(
    loop: ClosedLoop,
    reference: Reference,
    *,
    duration: float,
    true_params: BoucWenParams | None = None,
    window: Any = None,
    solver: ContinuousSolver | None = None,
) -> SimulationResult:
    """Continuous-time closed loop (paper Section 4.2), solved with a stiff method.

    Plant eq. (2), observer eq. (3) (``"phso"``) or eq. (21) (``"eso"``), controller
    eq. (12), all in continuous time. ``u'`` is handled exactly by solving the implicit
    relation (module docstring), or through an amplifier state when
    ``solver.amplifier_bandwidth`` (rad/s) is given.

    Parameters
    ----------
    loop : ClosedLoop
        Its model, observer (PHSO or ESO), continuous controller (eq. 12 with its
        ``u_limits``: on a bound ``u' = 0``), start and divergence limit; ``dt`` and
        the delay are not used.
    reference : Reference
    duration : float
        s.
    true_params : BoucWenParams, optional
        The simulated plant (model mismatch).
    window : (float, float), optional
        Metrics window, as for :func:`simulate`.
    solver : ContinuousSolver, optional
        Method, tolerances, recording step, amplifier model.

    Returns
    -------
    SimulationResult
    """
    run = prepare(loop, reference, duration=duration, true_params=true_params, sampled=False)
    solver = ContinuousSolver() if solver is None else solver
    if not isinstance(solver, ContinuousSolver):
        raise InputError(f"solver must be a ContinuousSolver, got {solver!r}")
    loop.require_observer("the continuous simulation")
    if loop.observer.kind not in ("phso", "eso"):
        raise InputError(f"continuous observer must be 'phso' or 'eso', got {loop.observer.kind!r}")
    if getattr(loop.controller, "dt", None) is not None or loop.controller.estimate_limits:
        raise InputError(
            "the continuous loop runs eq. (12) in continuous form (make_controller(..., "
            "form='continuous')) without estimate limits"
        )
    grid = _grid(run, solver)
    rec, info = _integrate(run, solver, grid)
    settings = _settings(run, solver, grid, info, true_params is not None)
    return finish(run, rec, window=window, mode="continuous", settings=settings)


def _grid(run: Run, solver: ContinuousSolver) -> dict[str, Any]:
    """Recording instants, the largest step and the segments between the law's jumps."""
    duration, reference = run.duration, run.reference
    T = reference.period or duration
    output_dt = solver.output_dt
    if output_dt is None:
        output_dt = min(T, duration) / 5000.0
    output_dt = real(output_dt, "output_dt (s)", within=DT)
    max_step = output_dt if solver.max_step is None else solver.max_step
    n_out = int(math.floor(duration / output_dt * (1 + 1e-12))) + 1
    t_out = np.minimum(np.arange(n_out) * output_dt, duration)
    amp = solver.amplifier_bandwidth is not None
    bps = [] if amp else _breakpoints(reference, duration)
    return {
        "output_dt": output_dt,
        "max_step": max_step,
        "t_out": t_out,
        "edges": [0.0, *bps, duration],
    }


class _Dynamics:
    """The continuous loop's right-hand side, its law and its jumps."""

    def __init__(self, run: Run, solver: ContinuousSolver):
        loop = run.loop
        self.params, self.tp = loop.model, run.true_params[0]
        ctrl = loop.controller
        self.Kx, self.Kr = ctrl.linear_gains()
        self.ulo, self.uhi = ctrl.u_limits if ctrl.u_limits else (-math.inf, math.inf)
        self.l1, self.l2, self.l3 = (float(v) for v in loop.observer.gains)
        self.phso = loop.observer.kind == "phso"
        self.wc = solver.amplifier_bandwidth
        self.ref3 = _scalar_reference(run.reference)
        self.seg = [0.0, run.duration]  # the open segment integrated (reference one-sided)

    def u_cmd(self, xh: np.ndarray, r: np.ndarray) -> float:
        return float(self.Kx @ xh + self.Kr @ r)

    def clip(self, u: float) -> float:
        return min(max(u, self.ulo), self.uhi)

    def rhs(self, tt: float, y: np.ndarray) -> np.ndarray:
        p, tp, Kx, Kr = self.params, self.tp, self.Kx, self.Kr
        a1, a2, a3, c = p.a1, p.a2, p.a3, Kx[2]  # c = a1/a3
        x, xh = y[:3], y[3:6]
        eps = 1e-12 * (1.0 + abs(tt))
        r, rdot = self.ref3(min(max(tt, self.seg[0] + eps), self.seg[1] - eps))
        ucmd = self.u_cmd(xh, r)
        innov = x[0] - xh[0]
        u = self.clip(ucmd) if self.wc is None else y[6]
        d = np.empty_like(y)
        dxh1 = xh[1] + self.l1 * innov
        dxh2 = -a1 * (xh[0] + xh[2]) - a2 * xh[1] + a3 * u + self.l2 * innov
        if self.wc is None:
            if self.ulo < ucmd < self.uhi:
                A = Kx[0] * dxh1 + Kx[1] * dxh2 + Kr @ rdot + c * self.l3 * innov
                udot = _solve_udot(A, c, p, xh[2]) if self.phso else A
            else:
                udot = 0.0
        else:
            udot = self.wc * (self.clip(ucmd) - u)
            d[6] = udot
        d[0] = x[1]
        d[1] = -tp.a1 * (x[0] + x[2]) - tp.a2 * x[1] + tp.a3 * u
        d[2] = _kappa(tp, math.copysign(1.0, udot), x[2]) * udot
        d[3] = dxh1
        d[4] = dxh2
        d[5] = (
            _kappa(p, math.copysign(1.0, udot), xh[2]) * udot if self.phso else 0.0
        ) + self.l3 * innov
        return d

    def initial(self, start: Any) -> np.ndarray:
        """The state at ``t = 0``: the hysteresis jumps from ``u_prev`` to ``u(0)``."""
        x0, xhat0 = np.array(start.x0, dtype=float), np.array(start.xhat0, dtype=float)
        u_prev = start.u_prev
        if self.wc is not None:
            return np.concatenate([x0, xhat0, [u_prev]])
        r0, _ = self.ref3(0.0)
        u0 = self.clip(self.u_cmd(xhat0, r0))
        x0[2] = hysteresis_increment(self.tp, x0[2], u_prev, u0)
        if self.phso:
            # the law depends on x3hat, which jumps with u: iterate the static fixed point
            for _ in range(50):
                xh = xhat0.copy()
                xh[2] = hysteresis_increment(self.params, xhat0[2], u_prev, u0)
                u_new = self.clip(self.u_cmd(xh, r0))
                if abs(u_new - u0) <= 1e-14 * (1 + abs(u0)):
                    break
                u0 = u_new
            xhat0 = xh
        return np.concatenate([x0, xhat0])

    def jump(self, tt: float, y: np.ndarray) -> np.ndarray:
        """``u`` jumps with ``x_d'`` at ``tt``: move both hysteresis states along the jump."""
        eps = 1e-9 * max(1.0, tt)
        rm, _ = self.ref3(tt - eps)
        rp, _ = self.ref3(tt + eps)
        um = self.clip(self.u_cmd(y[3:6], rm))
        up_ = self.clip(self.u_cmd(y[3:6], rp))
        y = y.copy()
        if self.phso:
            for _ in range(50):
                xh3 = hysteresis_increment(self.params, y[5], um, up_)
                yy = y.copy()
                yy[5] = xh3
                new = self.clip(self.u_cmd(yy[3:6], rp))
                if abs(new - up_) <= 1e-14 * (1 + abs(up_)):
                    break
                up_ = new
            y[5] = xh3
        y[2] = hysteresis_increment(self.tp, y[2], um, up_)
        return y


def _integrate(run: Run, solver: ContinuousSolver, grid: dict[str, Any]) -> tuple[dict, dict]:
    """Integrate segment by segment; the record and what the solver did."""
    from scipy.integrate import solve_ivp

    dyn = _Dynamics(run, solver)
    y0 = dyn.initial(run.start)
    w0 = math.sqrt(dyn.tp.a1)
    scale = np.array([1.0, w0, 1.0, 1.0, w0, 1.0] + ([1.0] if dyn.wc else []))
    atol_v = (1e-10 if solver.atol is None else float(solver.atol)) * scale
    t_out, edges = grid["t_out"], grid["edges"]
    limit = run.loop.divergence_limit
    Y = np.full((t_out.size, y0.size), np.nan)
    stable, status, y, nfev = True, "ok", y0, 0
    with np.errstate(all="ignore"):
        for i in range(len(edges) - 1):
            ta, tb = edges[i], edges[i + 1]
            if tb <= ta:
                continue
            if i > 0:
                y = dyn.jump(ta, y)
            last = i == len(edges) - 2
            sel = (t_out >= ta) & ((t_out <= tb) if last else (t_out < tb))
            t_eval = t_out[sel]
            extra = t_eval.size == 0 or t_eval[-1] < tb
            if extra:
                t_eval = np.append(t_eval, tb)
            dyn.seg[0], dyn.seg[1] = ta, tb
            try:
                sol = solve_ivp(
                    dyn.rhs, (ta, tb), y, method=solver.method, t_eval=t_eval,
                    rtol=solver.rtol, atol=atol_v, max_step=grid["max_step"],
                )  # fmt: skip
            except (InputError, ValueError, ArithmeticError) as err:
                stable, status = False, f"integration failed at t >= {ta:.6g} s: {err}"
                break
            nfev += sol.nfev
            got = sol.y.T[: sol.t.size - 1] if extra else sol.y.T
            idx = np.flatnonzero(sel)[: got.shape[0]]
            Y[idx] = got[: idx.size]
            if sol.status != 0 or sol.t.size < t_eval.size or not np.all(np.isfinite(sol.y)):
                t_fail = sol.t[-1] if sol.t.size else ta
                stable, status = False, f"integration failed at t = {t_fail:.6g} s: {sol.message}"
                break
            y = sol.y[:, -1]
            big = max(abs(y[0]), abs(y[2]), abs(y[3]), abs(y[5]))
            if big > limit or max(abs(y[1]), abs(y[4])) > limit * w0:
                stable, status = False, f"diverged before t = {tb:.6g} s"
                break
    ok = np.all(np.isfinite(Y), axis=1)
    m = int(np.argmin(ok)) if not np.all(ok) else t_out.size
    if m < t_out.size and stable:
        stable, status = False, "integration stopped early"
    t_rec = t_out[:m]
    X, XH = Y[:m, :3], Y[:m, 3:6]
    xd, vd, ad = (np.asarray(a, dtype=float) for a in run.reference.evaluate(t_rec))
    if dyn.wc is None:
        Kx, Kr = dyn.Kx, dyn.Kr
        U = np.clip(XH @ Kx + Kr[0] * xd + Kr[1] * vd + Kr[2] * ad, dyn.ulo, dyn.uhi)
    else:
        U = Y[:m, 6]
    rec = dict(t=t_rec, x=X, xhat=XH, u=U, x_d=xd, z=X[:, 0].copy(), stable=stable, status=status)
    return rec, {"y0": y0, "nfev": nfev, "atol": float(atol_v[0])}


def _settings(run: Run, solver: ContinuousSolver, grid: dict, info: dict, mismatch: bool):
    """Everything needed to reproduce the run (JSON-safe)."""
    loop = run.loop
    params, ctrl, y0 = loop.model, loop.controller, info["y0"]
    wc = solver.amplifier_bandwidth
    return {
        "plant": params.name,
        "true_plant": run.true_params[0].to_dict() if mismatch else None,
        "length_unit": params.length_unit,
        "input_unit": params.input_unit,
        "reference": run.reference.to_dict(),
        "observer": loop.observer.kind,
        "gains": list(loop.observer.gains),
        "controller": ctrl.to_dict(),
        "u_limits": list(ctrl.u_limits) if ctrl.u_limits else None,
        "duration": run.duration,
        "output_dt": grid["output_dt"],
        "method": solver.method,
        "rtol": solver.rtol,
        "atol_scale": info["atol"],
        "max_step": grid["max_step"],
        "udot": "implicit" if wc is None else f"amplifier state, {wc:g} rad/s",
        "x0": list(map(float, y0[:3])),
        "xhat0": list(map(float, y0[3:6])),
        "u_prev": float(run.start.u_prev),
        "rhs_evaluations": int(info["nfev"]),
    }
