"""What every simulation of a :class:`~bwdesign.control.loop.ClosedLoop` checks and shares.

:func:`prepare` validates a run once for the scalar, the batched and the continuous
simulation: the reference (a :class:`~bwdesign.model.references.Reference`, below the
Nyquist frequency of a sampled loop), the duration, the true plants (bounded unless
the loop allows otherwise, a sample time that suits each), the start and the metrics
window. :func:`finish` turns a record into a
:class:`~bwdesign.sim.result.SimulationResult`; :func:`diverged` names what left the
divergence limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..control.loop import ClosedLoop, Start
from ..errors import InputError
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_sample_time
from ..model.references import Reference
from ..validate import Range, below_nyquist, real
from .metrics import running_sum, steady_state_window, tracking_metrics
from .result import SimulationResult

__all__ = [
    "Run",
    "prepare",
    "finish",
    "diverged",
    "resolve_window",
    "disturbance_samples",
    "sensor_noise",
    "noise_kind",
    "kind_label",
    "NOISE_KINDS",
    "DURATION",
]

#: Supported run lengths (s).
DURATION = Range(0.0, 1e7, lo_open=True, unit="s")
#: The sensor noise of a run: ``"gaussian"``, ``noise_std`` times a standard normal per
#: sample; ``"bounded"``, ``+-noise_std`` with the sign of that normal (white, and at the
#: bound ``|n| <= noise_std`` of a certificate at every sample: what a certificate's
#: envelope and its falsifier must face). A kind may also be a *pattern*: an array of
#: values in [-1, 1], one per sample, and the noise is ``noise_std`` times it (a given
#: sequence within the bound, such as the falsifier's aimed noise,
#: :func:`bwdesign.sim.falsify.falsify`); its settings say ``"pattern"``.
NOISE_KINDS = ("gaussian", "bounded")


def noise_kind(kind: Any, shape: tuple[int, ...] | None = None) -> str | np.ndarray:
    """``kind`` checked: one of :data:`NOISE_KINDS`, or a pattern (``InputError`` otherwise).

    A pattern is returned as a read-only float array broadcast to ``shape`` (the run's
    samples, or scenarios by samples), each value finite and within [-1, 1].
    """
    if isinstance(kind, str):
        if kind not in NOISE_KINDS:
            raise InputError(f"noise_kind must be one of {', '.join(NOISE_KINDS)}, got {kind!r}")
        return kind
    if shape is None:
        raise InputError(f"noise_kind must be one of {', '.join(NOISE_KINDS)}, got {kind!r}")
    try:
        a = np.broadcast_to(np.asarray(kind, dtype=float), shape).copy()
    except (TypeError, ValueError):
        raise InputError(
            f"noise_kind must be one of {', '.join(NOISE_KINDS)} or a pattern of shape "
            f"{shape} (values in [-1, 1])"
        ) from None
    if not np.all(np.isfinite(a)) or np.any(np.abs(a) > 1):
        raise InputError("a noise_kind pattern must hold finite values within [-1, 1]")
    a.setflags(write=False)
    return a


def kind_label(kind: str | np.ndarray) -> str:
    """The name a run's settings give its noise kind (``"pattern"`` for a pattern)."""
    return kind if isinstance(kind, str) else "pattern"


def sensor_noise(
    noise_std: float, seed: int, n: int, kind: str | np.ndarray = "gaussian"
) -> np.ndarray:
    """The ``n`` noise samples of a run (:data:`NOISE_KINDS`), from
    ``numpy.random.default_rng(seed)``, or ``noise_std`` times a pattern; zeros for
    ``noise_std = 0``."""
    if noise_std <= 0:
        return np.zeros(n)
    if not isinstance(kind, str):
        return noise_std * np.asarray(kind, dtype=float)
    z = np.random.default_rng(seed).standard_normal(n)
    return noise_std * (z if kind == "gaussian" else np.sign(z))


@dataclass(frozen=True)
class Run:
    """A validated run: the loop, what it tracks, how long, against which plants.

    Attributes
    ----------
    loop : ClosedLoop
    reference : Reference
    duration : float
        Requested length (s).
    n : int
        Samples (sampled loops; 0 for a continuous run).
    start : Start
        The resolved start.
    true_params : tuple of BoucWenParams
        The simulated plant(s).
    """

    loop: ClosedLoop
    reference: Reference
    duration: float
    n: int
    start: Start
    true_params: tuple[BoucWenParams, ...]

    @property
    def t(self) -> np.ndarray:
        """Sample times (s)."""
        return np.arange(self.n) * self.loop.dt

    def reference_terms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x_d, x_d', x_d'')`` at the ``n + 1`` sample instants (one beyond the run)."""
        t = np.arange(self.n + 1) * self.loop.dt
        return tuple(np.asarray(a, dtype=float) for a in self.reference.evaluate(t))

    def baseline_feedforward(self) -> np.ndarray:
        """A baseline loop's feedforward per sample, for the input applied after sample
        ``k``'s law: at ``t_k + dt/2``, one sample later with a computation delay."""
        loop = self.loop
        lead = 0.5 * loop.dt + (loop.dt if loop.delay else 0.0)
        return loop.controller.feedforward_samples(self.reference, self.t + lead)


def prepare(
    loop: ClosedLoop,
    reference: Reference,
    *,
    duration: float,
    true_params: Any = None,
    sampled: bool = True,
) -> Run:
    """Check a run of ``loop`` (see the module docstring); ``true_params``: one plant,
    a list of plants (a batch) or ``None`` (the model itself).

    Raises
    ------
    InputError, UnboundedModelError
        Anything malformed, before any simulation (a diverging loop never raises).
    """
    if not isinstance(loop, ClosedLoop):
        raise InputError(
            f"loop must be a ClosedLoop (bwdesign.ClosedLoop(...) or ClosedLoop.from_config), "
            f"got {type(loop).__name__}"
        )
    if not isinstance(reference, Reference):
        raise InputError(
            "reference must be a bwdesign Reference (Sine, Triangle, Step or a subclass), "
            f"got {reference!r}"
        )
    duration = real(duration, "duration (s)", within=DURATION)
    if true_params is None:
        plants: list[Any] = [loop.model]
    elif isinstance(true_params, BoucWenParams):
        plants = [true_params]
    else:
        try:
            plants = list(true_params)
        except TypeError:
            raise InputError(
                f"true_params must be a BoucWenParams or a list of them, got {true_params!r}"
            ) from None
        if not plants:
            raise InputError("true_params holds no scenario")
    for i, tp in enumerate(plants):
        if not isinstance(tp, BoucWenParams):
            where = "true_params" if len(plants) == 1 else f"true_params[{i}]"
            raise InputError(f"{where} must be a BoucWenParams, got {type(tp).__name__}")
        require_bounded(tp, loop.allow_unbounded)
    n = 0
    if sampled:
        if loop.dt is None:
            raise InputError("a sampled simulation needs the loop's dt (ClosedLoop(dt=...))")
        for tp in plants:
            check_sample_time(tp, loop.dt)
        below_nyquist(reference, loop.dt)
        n = int(round(duration / loop.dt))
        if n < 2:
            raise InputError(
                f"duration {duration:g} s holds fewer than 2 samples of dt = {loop.dt:g} s"
            )
    return Run(
        loop=loop,
        reference=reference,
        duration=duration,
        n=n,
        start=loop.initial(reference),
        true_params=tuple(plants),
    )


def disturbance_samples(value: Any, run: Run, scenarios: int | None = None) -> Any:
    """The plant's input disturbance ``d_k`` per sample, held over the sample (or ``None``).

    ``value``: ``None``; a callable ``d(t)`` of the sample times ``run.t`` (s); or an
    array of the ``n`` samples. For a batch (``scenarios = N``) the callable or array may
    also give one row per scenario, shape ``(N, n)``; the result is then ``(n, N)``.
    One run gets a list of ``n`` floats. In the input unit.
    """
    if value is None:
        return None
    n = run.n
    try:
        d = np.asarray(value(run.t) if callable(value) else value, dtype=float)
    except (TypeError, ValueError) as err:
        raise InputError(f"input_disturbance must give numbers: {err}") from None
    shapes = [(n,)] if scenarios is None else [(n,), (scenarios, n)]
    if d.shape not in shapes:
        want = " or ".join(str(s) for s in shapes)
        raise InputError(f"input_disturbance must have shape {want} (samples), got {d.shape}")
    if not np.all(np.isfinite(d)):
        raise InputError("input_disturbance must be finite at every sample")
    if scenarios is None:
        return d.tolist()
    return np.ascontiguousarray(np.broadcast_to(d, (scenarios, n)).T)


def resolve_window(t: np.ndarray, reference: Reference, window: Any) -> tuple[float, float]:
    """The metrics window: ``window`` as given, or the default steady-state window."""
    if window is None:
        return steady_state_window(t, reference.period)
    try:
        w0, w1 = (float(v) for v in window)
    except (TypeError, ValueError):
        raise InputError(f"window must be (t_start, t_end) in s, got {window!r}") from None
    return (w0, w1)


def finish(
    run: Run,
    record: dict[str, Any],
    *,
    window: Any,
    mode: str,
    settings: dict[str, Any],
) -> SimulationResult:
    """The :class:`SimulationResult` of a record (``t, x, xhat, u, x_d, z, stable,
    status``), with its metrics over the window when the run stayed stable."""
    t, x, xhat = record["t"], record["x"], record["xhat"]
    xd = record["x_d"]
    stable, status = record["stable"], record["status"]
    e = x[:, 0] - xd
    metrics = None
    est = None
    win = resolve_window(t, run.reference, window) if t.size else (math.nan, math.nan)
    if stable and t.size:
        try:
            metrics = tracking_metrics(e, t, win)
            sel = (t >= win[0] - 1e-12) & (t <= win[1] + 1e-12)
            d = xhat[sel] - x[sel]
            if not run.loop.baseline:  # a baseline has no estimate
                est = tuple(float(v) for v in np.sqrt(running_sum(d * d) / len(d)))
        except InputError as err:
            stable, status = False, f"no metrics: {err}"
    return SimulationResult(
        t=t,
        x=x,
        xhat=xhat,
        u=record["u"],
        x_d=xd,
        e=e,
        z=record["z"],
        metrics=metrics,
        window=win,
        estimation_rmse=est,
        stable=stable,
        status=status,
        mode=mode,
        settings=settings,
    )


def diverged(limit, w0, x1, x2, x3, xh1, xh2, xh3, u) -> str | None:
    """What left the divergence limits (``None`` when nothing did)."""
    vals = (x1, x2, x3, xh1, xh2, xh3, u)
    if not all(math.isfinite(v) for v in vals):
        return "non-finite state"
    if max(abs(x1), abs(x3), abs(xh1), abs(xh3)) > limit:
        return f"displacement or hysteresis state beyond {limit:g}"
    if max(abs(x2), abs(xh2)) > limit * w0:
        return f"velocity beyond {limit * w0:g}"
    return None
