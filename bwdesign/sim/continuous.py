"""The continuous-time closed loop (:func:`simulate_continuous`); see :mod:`bwdesign.sim`."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_dt as _check_dt
from ..model.plant import hysteresis_increment
from ..model.references import Reference, Triangle
from ..observers.gains import check_gains
from .closed_loop import _controller, _finish, _finite_nonneg, _state
from .result import SimulationResult

__all__ = ["simulate_continuous"]


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
    params: BoucWenParams,
    reference: Reference,
    *,
    duration: float,
    observer: str = "phso",
    gains: Any,
    lambda1: float,
    lambda2: float,
    u_limits: Any = None,
    true_params: BoucWenParams | None = None,
    x0: Any = None,
    xhat0: Any = None,
    u_prev: float = 0.0,
    output_dt: float | None = None,
    method: str = "Radau",
    rtol: float = 1e-8,
    atol: float | None = None,
    max_step: float | None = None,
    amplifier_bandwidth: float | None = None,
    window: Any = None,
    divergence_limit: float = 1e6,
    allow_unbounded: bool = False,
) -> SimulationResult:
    """Continuous-time closed loop (paper Section 4.2), solved with a stiff method.

    Plant eq. (2), observer eq. (3) (``"phso"``) or eq. (21) (``"eso"``),
    controller eq. (12), all in continuous time. ``u'`` is handled exactly by
    solving the implicit relation (module docstring), or through an
    amplifier state when ``amplifier_bandwidth`` (rad/s) is given.

    Parameters
    ----------
    params : BoucWenParams
        Model of observer and controller.
    reference : Reference
    duration : float
        s.
    observer : {"phso", "eso"}
    gains : array_like, shape (3,)
        Continuous observer gains.
    lambda1, lambda2 : float
        Eq. (12) constants (1/s).
    u_limits : (float, float), optional
        Clip u (V); on a bound ``u' = 0``.
    true_params : BoucWenParams, optional
        The simulated plant (model mismatch).
    x0, xhat0 : array_like, shape (3,), optional
        Initial plant state and estimate (default zeros).
    u_prev : float
        Input before ``t = 0`` (V): the hysteresis jumps from it to ``u(0)``.
    output_dt : float, optional
        Spacing of the recorded samples (s); default ``min(period, duration)/5000``.
    method : str
        ``solve_ivp`` method: "Radau" (default), "BDF" or "LSODA".
    rtol, atol : float
        Tolerances; ``atol`` defaults to ``1e-10`` times each state's scale.
    max_step : float, optional
        Largest step (s); default ``output_dt``.
    amplifier_bandwidth : float, optional
        Model the amplifier as ``u' = wc (u_cmd - u)`` (rad/s) instead of solving
        the implicit relation.
    window, divergence_limit, allow_unbounded
        As for :func:`simulate`.

    Returns
    -------
    SimulationResult
    """
    from scipy.integrate import solve_ivp

    if observer not in ("phso", "eso"):
        raise InputError(f"continuous observer must be 'phso' or 'eso', got {observer!r}")
    tp = params if true_params is None else true_params
    require_bounded(params, allow_unbounded)
    require_bounded(tp, allow_unbounded)
    duration = _finite_nonneg(duration, "duration (s)")
    if duration <= 0:
        raise InputError("duration must be > 0 s")
    l = check_gains(params, gains)
    ctrl = _controller(params, None, lambda1, lambda2, "continuous", None, u_limits, None)
    Kx, Kr = ctrl.linear_gains()
    ulo, uhi = ctrl.u_limits if ctrl.u_limits else (-math.inf, math.inf)
    x0 = _state(x0, "x0")
    xhat0 = _state(xhat0, "xhat0")
    if method not in ("Radau", "BDF", "LSODA"):
        raise InputError(f"method must be a stiff solver (Radau, BDF, LSODA), got {method!r}")
    T = reference.period or duration
    if output_dt is None:
        output_dt = min(T, duration) / 5000.0
    output_dt = _check_dt(output_dt)
    if max_step is None:
        max_step = output_dt
    wc = None
    if amplifier_bandwidth is not None:
        wc = float(amplifier_bandwidth)
        if not math.isfinite(wc) or wc <= 0:
            raise InputError(f"amplifier_bandwidth must be > 0 rad/s, got {amplifier_bandwidth}")
    phso = observer == "phso"
    a1, a2, a3 = params.a1, params.a2, params.a3
    c = Kx[2]  # a1/a3
    l1, l2, l3 = (float(v) for v in l)

    ref3 = _scalar_reference(reference)

    def u_cmd(xh: np.ndarray, r: np.ndarray) -> float:
        return float(Kx @ xh + Kr @ r)

    seg = [0.0, duration]  # the open segment being integrated (reference one-sided there)

    def rhs(tt: float, y: np.ndarray) -> np.ndarray:
        x = y[:3]
        xh = y[3:6]
        eps = 1e-12 * (1.0 + abs(tt))
        r, rdot = ref3(min(max(tt, seg[0] + eps), seg[1] - eps))
        ucmd = u_cmd(xh, r)
        innov = x[0] - xh[0]
        if wc is None:
            u = min(max(ucmd, ulo), uhi)
        else:
            u = y[6]
        d = np.empty_like(y)
        dxh1 = xh[1] + l1 * innov
        dxh2 = -a1 * (xh[0] + xh[2]) - a2 * xh[1] + a3 * u + l2 * innov
        if wc is None:
            if ulo < ucmd < uhi:
                A = Kx[0] * dxh1 + Kx[1] * dxh2 + Kr @ rdot + c * l3 * innov
                if phso:
                    udot = _solve_udot(A, c, params, xh[2])
                else:
                    udot = A
            else:
                udot = 0.0
        else:
            udot = wc * (min(max(ucmd, ulo), uhi) - u)
            d[6] = udot
        d[0] = x[1]
        d[1] = -tp.a1 * (x[0] + x[2]) - tp.a2 * x[1] + tp.a3 * u
        d[2] = _kappa(tp, math.copysign(1.0, udot), x[2]) * udot
        d[3] = dxh1
        d[4] = dxh2
        d[5] = (
            _kappa(params, math.copysign(1.0, udot), xh[2]) * udot if phso else 0.0
        ) + l3 * innov
        return d

    # initial input and hysteresis jump from u_prev
    r0, _ = ref3(0.0)
    u0 = min(max(u_cmd(xhat0, r0), ulo), uhi)
    if wc is None:
        x0 = x0.copy()
        x0[2] = hysteresis_increment(tp, x0[2], u_prev, u0)
        if phso:
            # the law depends on x3hat, which jumps with u: iterate the static fixed point
            for _ in range(50):
                xh = xhat0.copy()
                xh[2] = hysteresis_increment(params, xhat0[2], u_prev, u0)
                u_new = min(max(u_cmd(xh, r0), ulo), uhi)
                if abs(u_new - u0) <= 1e-14 * (1 + abs(u0)):
                    break
                u0 = u_new
            xhat0 = xh
        y0 = np.concatenate([x0, xhat0])
    else:
        y0 = np.concatenate([x0, xhat0, [u_prev]])
    w0 = math.sqrt(tp.a1)
    scale = np.array([1.0, w0, 1.0, 1.0, w0, 1.0] + ([1.0] if wc else []))
    if atol is None:
        atol_v = 1e-10 * scale
    else:
        atol_v = float(atol) * scale

    n_out = int(math.floor(duration / output_dt * (1 + 1e-12))) + 1
    t_out = np.minimum(np.arange(n_out) * output_dt, duration)
    bps = _breakpoints(reference, duration) if wc is None else []
    edges = [0.0, *bps, duration]
    Y = np.full((n_out, y0.size), np.nan)
    stable, status = True, "ok"
    y = y0
    nfev = 0

    def jump(tt: float, y: np.ndarray) -> np.ndarray:
        # u jumps with x_d' at tt: move both hysteresis states along the jump
        eps = 1e-9 * max(1.0, tt)
        rm, _ = ref3(tt - eps)
        rp, _ = ref3(tt + eps)
        um = min(max(u_cmd(y[3:6], rm), ulo), uhi)
        up_ = min(max(u_cmd(y[3:6], rp), ulo), uhi)
        y = y.copy()
        if phso:
            for _ in range(50):
                xh3 = hysteresis_increment(params, y[5], um, up_)
                yy = y.copy()
                yy[5] = xh3
                new = min(max(u_cmd(yy[3:6], rp), ulo), uhi)
                if abs(new - up_) <= 1e-14 * (1 + abs(up_)):
                    break
                up_ = new
            y[5] = xh3
        y[2] = hysteresis_increment(tp, y[2], um, up_)
        return y

    with np.errstate(all="ignore"):
        for i in range(len(edges) - 1):
            ta, tb = edges[i], edges[i + 1]
            if tb <= ta:
                continue
            if i > 0:
                y = jump(ta, y)
            last = i == len(edges) - 2
            sel = (t_out >= ta) & ((t_out <= tb) if last else (t_out < tb))
            t_eval = t_out[sel]
            extra = t_eval.size == 0 or t_eval[-1] < tb
            if extra:
                t_eval = np.append(t_eval, tb)
            seg[0], seg[1] = ta, tb
            try:
                sol = solve_ivp(
                    rhs,
                    (ta, tb),
                    y,
                    method=method,
                    t_eval=t_eval,
                    rtol=rtol,
                    atol=atol_v,
                    max_step=max_step,
                )
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
            if big > divergence_limit or max(abs(y[1]), abs(y[4])) > divergence_limit * w0:
                stable, status = False, f"diverged before t = {tb:.6g} s"
                break
    ok = np.all(np.isfinite(Y), axis=1)
    m = int(np.argmin(ok)) if not np.all(ok) else n_out
    if m < n_out and stable:
        stable, status = False, "integration stopped early"
    t_rec = t_out[:m]
    X = Y[:m, :3]
    XH = Y[:m, 3:6]
    xd, vd, ad = (np.asarray(a, dtype=float) for a in reference.evaluate(t_rec))
    if wc is None:
        U = np.clip(XH @ Kx + Kr[0] * xd + Kr[1] * vd + Kr[2] * ad, ulo, uhi)
    else:
        U = Y[:m, 6]
    settings = {
        "plant": params.name,
        "true_plant": tp.to_dict() if true_params is not None else None,
        "length_unit": params.length_unit,
        "input_unit": params.input_unit,
        "reference": reference.to_dict(),
        "observer": observer,
        "gains": l.tolist(),
        "controller": ctrl.to_dict(),
        "u_limits": list(ctrl.u_limits) if ctrl.u_limits else None,
        "duration": duration,
        "output_dt": output_dt,
        "method": method,
        "rtol": rtol,
        "atol_scale": float(atol_v[0]),
        "max_step": max_step,
        "udot": "implicit" if wc is None else f"amplifier state, {wc:g} rad/s",
        "x0": list(map(float, y0[:3])),
        "xhat0": list(map(float, y0[3:6])),
        "u_prev": float(u_prev),
        "rhs_evaluations": int(nfev),
    }
    return _finish(
        t=t_rec,
        x=X,
        xhat=XH,
        u=U,
        xd=xd,
        z=X[:, 0].copy(),
        reference=reference,
        window=window,
        stable=stable,
        status=status,
        mode="continuous",
        settings=settings,
    )
