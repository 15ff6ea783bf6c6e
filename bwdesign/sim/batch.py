"""Batched sampled-data closed loop: N scenarios in one compiled call.

:func:`simulate_batch` runs the loop of :func:`bwdesign.sim.simulate` (the exact
ZOH plant with each scenario's *true* parameters, the PHSO, ESO or PHDO on the common
model, the linear law of a :class:`~bwdesign.TrackingController` or
:class:`~bwdesign.DiscreteTrackingController`, sensor noise, a one-sample delay,
saturation and estimate clipping) for ``N`` scenarios. The sample step is
:mod:`bwdesign.sim.kernel`'s, written as scalar code and compiled
(:mod:`bwdesign.sim.compiled`): the same operations in the same order on the same
matrices (:func:`bwdesign.sim.zoh.true_matrices`), the metrics added in the same order
(:func:`bwdesign.sim.metrics.running_sum`), so each scenario's metrics equal
:func:`simulate`'s on the same inputs to the bit (tested); the noise of scenario ``i``
is ``noise_std[i] * default_rng(seeds[i]).standard_normal(n)`` (or its sign, for a
bounded noise: :func:`bwdesign.sim.run.sensor_noise`), exactly as
:func:`simulate` draws it, scenarios taken in groups so that at most a few million
noise values are held at once.

Not batched (use :func:`simulate`): the UKF, observer objects or factories, and
controllers with ``hysteresis_jump``. Baseline loops (no observer) are batched on
:func:`~bwdesign.sim.compiled.baseline_batch` (the step of
:func:`~bwdesign.sim.kernel.advance_baseline`); their estimation statistics are NaN.

Only what a sweep needs is kept per scenario: the steady-state window's
statistics (MAXE, ME, RMSE, estimation RMSE and max error per state), stability
and the divergence status; a scenario's full record is replayed with
:func:`simulate`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..control.loop import ClosedLoop
from ..errors import InputError
from ..model.params import BoucWenParams
from ..model.references import Reference
from ..observers.spec import GAIN_KINDS
from . import kernel_process
from .kernel import SCALAR, LoopConstants, discrete_observer_gains, hysteresis_increment_batch
from .run import Run, disturbance_samples, diverged, kind_label, prepare, resolve_window
from .run import noise_kind as check_noise_kind
from .zoh import true_matrices

__all__ = ["BatchResult", "simulate_batch", "hysteresis_increment_batch"]

BATCH_OBSERVERS = GAIN_KINDS
#: Noise values held at once: scenarios are run in groups of at most this many samples.
_CHUNK_VALUES = 4_000_000


@dataclass(frozen=True)
class BatchResult:
    """Per-scenario outcome of :func:`simulate_batch` (arrays of length N).

    Attributes
    ----------
    stable : ndarray of bool
    status : tuple of str
        ``"ok"`` or the divergence message :func:`simulate` would give.
    maxe, me, rmse : ndarray
        Tracking-error statistics over ``window`` (length unit); NaN when unstable.
    estimation_rmse : ndarray, shape (N, 3)
        RMS of ``xhat - x`` per state over ``window``; NaN when unstable.
    estimation_maxe : ndarray, shape (N, 3)
        Max of ``|xhat - x|`` per state over ``window``; NaN when unstable.
    input_rate_max : ndarray
        Largest ``|u_k - u_{k-1}| / dt`` of the applied input over ``window``
        (input unit/s); NaN when unstable.
    input_accel_max : ndarray
        Largest ``|u_k - 2 u_{k-1} + u_{k-2}| / dt^2`` of the applied input over
        ``window`` (input unit/s^2), the second-difference envelope a robust certificate
        may assume (:func:`bwdesign.certify_robust`'s ``uddot_max``); NaN when unstable.
    saturated_fraction : ndarray
        Share of the samples whose applied input is at a ``u_limits`` bound (the run's
        every sample, as :attr:`bwdesign.sim.SimulationResult.saturated_fraction`; a
        diverged one's samples up to the divergence); 0 without limits.
    window : (float, float)
        Metrics window (s).
    samples : int
        Samples per scenario.
    settings : dict
        What was simulated (common to every scenario).
    """

    stable: np.ndarray
    status: tuple[str, ...]
    maxe: np.ndarray
    me: np.ndarray
    rmse: np.ndarray
    estimation_rmse: np.ndarray
    estimation_maxe: np.ndarray
    input_rate_max: np.ndarray
    input_accel_max: np.ndarray
    saturated_fraction: np.ndarray
    window: tuple[float, float]
    samples: int
    settings: dict[str, Any] = field(repr=False)

    def __len__(self) -> int:
        return int(self.stable.size)


def _per_scenario(value: Any, n: int, name: str) -> np.ndarray:
    try:
        a = np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number or one per scenario ({n})") from None
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise InputError(f"{name} must be finite and >= 0 for every scenario")
    return a


def simulate_batch(
    loop: ClosedLoop,
    reference: Reference,
    true_params: list[BoucWenParams],
    *,
    duration: float,
    noise_std: Any = 0.0,
    seeds: Any = 0,
    window: Any = None,
    input_disturbance: Any = None,
    noise_kind: Any = "gaussian",
) -> BatchResult:
    """Run the sampled loop ``loop`` for every true parameter set in ``true_params``.

    Parameters
    ----------
    loop : ClosedLoop
        Model, observer (PHSO, ESO or PHDO; for the PHDO the ``xhat`` metrics are of
        the lumped ``x3 + d``, which starts from ``xhat0[2]`` with ``d = 0``), law (its
        ``u_limits``, ``estimate_limits`` and integral action apply; ``hysteresis_jump``
        is not batched), dt, delay, start: common to every scenario.
    reference : Reference
    true_params : list of BoucWenParams, length N
        The simulated plant of each scenario.
    duration : float
        Run length (s), as for :func:`simulate`.
    noise_std : float or array_like, shape (N,)
        Sensor noise std per scenario (length unit).
    seeds : int or array_like of int, shape (N,)
        Noise seed per scenario (``numpy.random.default_rng``).
    window : (float, float), optional
        Metrics window (s), as for :func:`simulate`.
    input_disturbance : callable or array_like, optional
        The plant's input disturbance, as for :func:`simulate`: common to every
        scenario (``n`` samples) or one row per scenario (shape ``(N, n)``).
    noise_kind : {"gaussian", "bounded"} or array_like, shape (N, n) or (n,)
        As for :func:`simulate` (:data:`bwdesign.sim.run.NOISE_KINDS`); a pattern is one
        row per scenario (or one row for all), scenario ``i``'s noise ``noise_std[i]``
        times its row.

    Returns
    -------
    BatchResult
    """
    if not isinstance(true_params, list | tuple):
        true_params = list(true_params) if true_params is not None else None
    run = prepare(loop, reference, duration=duration, true_params=true_params or [])
    loop = run.loop
    if not loop.baseline and loop.observer.kind not in BATCH_OBSERVERS:
        raise InputError(
            f"batched observers are {', '.join(BATCH_OBSERVERS)}, got {loop.observer.kind!r}"
        )
    if loop.controller.hysteresis_jump:
        raise InputError("hysteresis_jump is not batched; use bwdesign.simulate")
    N = len(run.true_params)
    noise_std = _per_scenario(noise_std, N, "noise_std")
    seeds = np.broadcast_to(np.asarray(seeds), (N,))
    if seeds.dtype.kind not in "iu" or np.any(seeds < 0):
        raise InputError("seeds must be integers >= 0")
    noise = (noise_std, seeds, check_noise_kind(noise_kind, (N, run.n)))
    t = run.t
    win = resolve_window(t, reference, window)
    in_win = (t >= win[0] - 1e-12) & (t <= win[1] + 1e-12)
    if not np.any(in_win):
        raise InputError(f"window {win} holds no sample")
    dist = disturbance_samples(input_disturbance, run, N)
    acc = (_run_batch_baseline if loop.baseline else _run_batch)(run, in_win, noise, dist)
    stable = acc["alive"].copy()
    count = acc["count"]
    settings = {
        "plant": loop.model.name,
        "reference": reference.to_dict(),
        "observer": None if loop.baseline else loop.observer.kind,
        "gains": None if loop.baseline else list(loop.observer.gains),
        "controller": loop.controller.to_dict(),
        "dt": loop.dt,
        "duration": run.n * loop.dt,
        "delay": loop.delay,
        "compensate_delay": loop.compensate_delay,
        "x0": list(run.start.x0),
        "xhat0": list(run.start.xhat0),
        "u_prev": run.start.u_prev,
    }
    if kind_label(noise[2]) != "gaussian":
        settings["noise_kind"] = kind_label(noise[2])
    return BatchResult(
        stable=stable,
        status=tuple(acc["status"]),
        maxe=np.where(stable, acc["max_abs"], np.nan),
        me=np.where(stable, acc["sum_abs"] / count, np.nan),
        rmse=np.where(stable, np.sqrt(acc["sum_sq"] / count), np.nan),
        estimation_rmse=np.where(
            stable[:, None], np.sqrt(np.stack(acc["est_sq"], axis=1) / count), np.nan
        ),
        estimation_maxe=np.where(stable[:, None], np.stack(acc["est_max"], axis=1), np.nan),
        input_rate_max=np.where(stable, acc["du_max"] / loop.dt, np.nan),
        input_accel_max=np.where(stable, acc["d2u_max"] / loop.dt**2, np.nan),
        saturated_fraction=acc["saturated"] / np.where(stable, run.n, acc["ran"]),
        window=(float(win[0]), float(win[1])),
        samples=run.n,
        settings=settings,
    )


def _plant_rows(T: dict[str, np.ndarray], limit: float) -> np.ndarray:
    """The compiled runners' ``plant`` array (:func:`.compiled.observer_batch`)."""
    names = ("p11", "p12", "p13", "p21", "p22", "p23", "g1", "g2", "alpha", "beta", "gamma")
    cols = [T[k] for k in names] + [limit * T["w0"]]
    return np.ascontiguousarray(np.stack(cols, axis=1), dtype=float)


def _chunks(run: Run, noise: tuple, dist):
    """Scenario ranges of at most ``_CHUNK_VALUES`` noise values:
    ``(lo, hi, noise, dist, noisy)``.

    ``noise`` = ``(noise_std, seeds, kind)``; scenario ``i``'s noise is
    :func:`~.run.sensor_noise` of ``noise_std[i]`` and ``seeds[i]``, as :func:`simulate`
    draws it; ``dist`` rows are scenarios (none, or one per scenario). The chunk's noise
    is given as what draws it, ``(seeds, std, bounded)`` (:func:`.compiled.noise_rows`):
    the runner draws it where it runs (:mod:`.kernel_process`), no array is sent; a
    pattern's noise is sent as the array it is.
    """
    noise_std, seeds, kind = noise
    n, N = run.n, noise_std.size
    noisy = bool(np.any(noise_std > 0))
    step = max(1, _CHUNK_VALUES // max(n, 1)) if noisy or dist is not None else N
    for lo in range(0, N, step):
        hi = min(N, lo + step)
        drawn = None
        if noisy and not isinstance(kind, str):  # a pattern, scaled row by row
            drawn = np.ascontiguousarray(noise_std[lo:hi, None] * kind[lo:hi])
        elif noisy:
            std = np.ascontiguousarray(noise_std[lo:hi], dtype=float)
            drawn = ([int(v) for v in seeds[lo:hi]], std, kind != "gaussian")
        d = np.zeros((0, 1)) if dist is None else np.ascontiguousarray(dist[:, lo:hi].T)
        yield lo, hi, drawn, d, noisy


def _finish(out: np.ndarray, T: dict[str, np.ndarray], limit: float, dt: float, count: int):
    """The accumulated statistics and each scenario's status from the runners' ``out``."""
    alive = out[:, 10] != 0.0
    status = ["ok"] * out.shape[0]
    for i in np.flatnonzero(~alive):
        status[i] = _stopped(out[i, 11:19], limit, T["w0"][i], dt)
    return {
        "sum_abs": out[:, 0].copy(),
        "sum_sq": out[:, 1].copy(),
        "max_abs": out[:, 2].copy(),
        "est_sq": [out[:, 3 + j].copy() for j in range(3)],
        "est_max": [out[:, 6 + j].copy() for j in range(3)],
        "du_max": out[:, 9].copy(),
        "d2u_max": out[:, 20].copy(),
        "saturated": out[:, 19].copy(),
        # a diverged scenario's samples run, up to and including the divergence
        "ran": out[:, 11] + 1.0,
        "count": count,
        "alive": alive,
        "status": status,
    }


def _stopped(where: np.ndarray, limit: float, w0: float, dt: float) -> str:
    """The status of a run the kernel stopped: ``where`` = its step, then its state there
    (x1, x2, x3, xhat1, xhat2, xhat_lumped, u_a), as the compiled runners write them."""
    why = diverged(limit, w0, *where[1:8]) or "non-finite state"
    return f"diverged at t = {(int(where[0]) + 1) * dt:.6g} s: {why}"


def _run_batch_baseline(run: Run, in_win: np.ndarray, noise, dist) -> dict:
    """A baseline loop for every scenario (:func:`.compiled.baseline_batch`)."""
    loop, N = run.loop, len(run.true_params)
    dt, limit = loop.dt, loop.divergence_limit
    xd = run.reference_terms()[0]
    ff = run.baseline_feedforward()
    c = loop.controller.constants()
    law = np.array([c.kp, c.ki, c.da, c.db, c.dt, c.lo, c.hi], dtype=float)
    win = np.append(in_win, False).astype(float)
    ref = np.ascontiguousarray(np.stack([np.append(ff, 0.0), xd, win]))
    T = true_matrices(list(run.true_params), dt)
    plant = _plant_rows(T, limit)
    start = run.start
    q0 = loop.controller.start(start.x0[0], start.u_prev, ff[0]).q
    x0 = [float(v) for v in start.x0]
    st = np.array([*x0, float(start.u_prev), float(q0)])
    out = np.zeros((N, 21))
    for lo, hi, rows, d, noisy in _chunks(run, noise, dist):
        flags = np.array([float(bool(loop.delay)), limit, float(noisy)])
        args = (plant[lo:hi], law, ref, flags, st, rows, d, out[lo:hi])
        kernel_process.run("baseline_drawn", args, 7)
    acc = _finish(out, T, limit, dt, int(np.count_nonzero(in_win)))
    nan = np.full(N, np.nan)
    acc.update(est_sq=[nan] * 3, est_max=[nan] * 3)
    return acc


def _observer_arrays(run: Run, noisy: bool) -> tuple:
    """``(plant, consts, ref without the window, T)``: :func:`.compiled.observer_batch`'s
    arrays for ``run`` (the window row is zeros) and the plants' ZOH matrices."""
    loop = run.loop
    dt, limit = loop.dt, loop.divergence_limit
    ref3 = run.reference_terms()
    c = LoopConstants(loop, discrete_observer_gains(loop), ref3, SCALAR)
    m = loop.model
    model = np.array(
        [c.m11, c.m12, c.m13, c.m21, c.m22, c.m23, c.mg1, c.mg2, m.alpha, m.beta, m.gamma]
    )
    gains = np.array([c.K1, c.K2, c.K3, c.K4])
    lim = np.array([v for pair in c.limits for v in pair] if c.clip else [0.0] * 6, dtype=float)
    law = np.array(
        [c.kx1, c.kx2, c.kx3, c.ki, c.cdt, c.ulo, c.uhi, float(c.integral), float(c.clip)]
    )
    ref = np.stack([np.asarray(c.ff, dtype=float), ref3[0], np.zeros(run.n + 1)])
    T = true_matrices(list(run.true_params), dt)
    start = run.start
    st = np.array([*(float(v) for v in start.x0), *(float(v) for v in start.xhat0)] + [0.0])
    st[6] = float(start.u_prev)
    flags = np.array(
        [float(c.four), float(c.phso), float(bool(c.delay)), float(bool(c.compensate)),
         limit, float(noisy)]
    )  # fmt: skip
    return _plant_rows(T, limit), (model, gains, law, lim, flags, st), ref, T


def _run_batch(run: Run, in_win: np.ndarray, noise, dist) -> dict:
    """The loop for every scenario (:func:`.compiled.observer_batch`, the step of
    :mod:`bwdesign.sim.kernel` compiled)."""
    loop = run.loop
    plant, consts, ref, T = _observer_arrays(run, False)
    ref[2] = np.append(in_win, False).astype(float)
    ref = np.ascontiguousarray(ref)
    out = np.zeros((len(run.true_params), 21))
    for lo, hi, rows, d, noisy in _chunks(run, noise, dist):
        flags = consts[4].copy()
        flags[5] = float(noisy)
        chunk = (*consts[:4], flags, consts[5])
        kernel_process.run("observer_drawn", (plant[lo:hi], chunk, ref, rows, d, out[lo:hi]), 5)
    return _finish(out, T, loop.divergence_limit, loop.dt, int(np.count_nonzero(in_win)))


def observer_record(run: Run, noise: np.ndarray, dist: np.ndarray | None) -> dict[str, Any]:
    """The record of :func:`~.closed_loop.simulate`'s sample loop for ``run`` (one plant,
    its ``noise`` and ``dist`` samples, the law without ``hysteresis_jump``), run by the
    compiled step (:func:`.compiled.observer_trace`): ``x``, ``xhat``, ``u``, ``z`` (up to
    the divergence), ``m`` (samples kept), ``stable`` and ``status``, the scalar loop's
    numbers to the bit."""
    loop, n = run.loop, run.n
    plant, consts, ref, T = _observer_arrays(run, True)
    d = np.zeros((0, 1)) if dist is None else np.ascontiguousarray(np.reshape(dist, (1, -1)))
    rows = np.ascontiguousarray(np.reshape(noise, (1, -1)), dtype=float)
    trace = np.zeros((n + 1, 9))
    kernel_process.run("observer_trace", (plant, consts, ref, rows, d, trace), 5)
    last = trace[n]
    stable, status, m = bool(last[0] != 0.0), "ok", n
    if not stable:
        m = int(last[1]) + 1
        status = _stopped(last[1:9], loop.divergence_limit, T["w0"][0], loop.dt)
    x, xhat = trace[:n, 0:3].copy(), trace[:n, 3:6].copy()
    u, z = trace[:n, 6].copy(), trace[:n, 7].copy()
    return dict(x=x, xhat=xhat, u=u, z=z, m=m, stable=stable, status=status)
