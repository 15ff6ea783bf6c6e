"""Monte Carlo sweeps: scenarios drawn from an uncertainty box, run in chunks, locally or on Dask.

- :func:`draw_scenarios` draws the true parameters (uniform in the box, or a
  normal truncated to the box whose half-widths are ``level`` confidence
  intervals) and a noise seed per scenario from one seeded generator, all at
  once: the draw depends only on the seed, never on chunks or workers.
- :func:`run_sweep` splits the scenarios into chunks and runs each with
  :func:`bwdesign.sim.batch.simulate_batch`, in this process (``workers=0``), on
  a ``dask.distributed`` LocalCluster of worker processes (the default), or on an
  existing cluster (``scheduler="tcp://host:port"``). A chunk that fails is retried
  and then reported (:class:`SweepError`), never dropped. The rows are put back in
  scenario order, so the result is the same for any chunking and any number of
  workers.

This module is the only one that imports dask (inside functions).
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from statistics import NormalDist
from typing import Any

import numpy as np

from .. import interrupts
from ..control.controllers import TrackingController
from ..errors import BWDesignError, InputError, UnboundedModelError
from ..extras import require
from ..model.params import MODEL_FIELDS, BoucWenParams
from ..model.references import Reference
from ..observers.gains import disturbance_gains_from
from .batch import BATCH_OBSERVERS, simulate_batch
from .start import start_on_reference

__all__ = [
    "SweepSpec",
    "SweepError",
    "METRIC_COLUMNS",
    "draw_scenarios",
    "run_chunk",
    "run_sweep",
    "box_bounds",
    "check_box",
    "spec_from_config",
    "bounds_from_config",
]

DISTRIBUTIONS = ("uniform", "normal")
#: Result columns per (scenario, observer) row, after the drawn ones.
METRIC_COLUMNS = ("maxe", "me", "rmse", "est_rmse_x1", "est_rmse_x2", "est_rmse_x3")


class SweepError(BWDesignError, RuntimeError):
    """A sweep could not be completed (a chunk failed after its retries, no scheduler)."""


@dataclass(frozen=True)
class SweepSpec:
    """What every scenario shares: the model, the loop and the run (picklable for Dask).

    Attributes
    ----------
    params : BoucWenParams
        The model of the observer and the controller.
    reference : Reference
    dt, duration : float
        Sample time and run length (s).
    controller : TrackingController
    gains : tuple of 3 floats
        Continuous observer gains (the PHDO runs ``(l1, l2, 0, l3)`` of them).
    observers : tuple of str
        Observers run on every scenario (``"phso"``, ``"eso"``).
    noise_std : float
        Sensor noise std (length unit).
    delay : bool
        One-sample computation delay.
    start : {"reference", "rest"}
        Every scenario starts on the reference (:func:`bwdesign.start_on_reference`,
        as the report's runs) or from rest.
    """

    params: BoucWenParams
    reference: Reference
    dt: float
    duration: float
    controller: TrackingController
    gains: tuple[float, float, float]
    observers: tuple[str, ...] = ("phso",)
    noise_std: float = 0.0
    delay: bool = False
    start: str = "reference"

    def gains_for(self, observer: str) -> tuple[float, ...]:
        """The continuous gains ``observer`` runs: ``gains``; ``(l1, l2, 0, l3)`` for the PHDO."""
        return disturbance_gains_from(self.gains) if observer == "phdo" else tuple(self.gains)

    def __post_init__(self) -> None:
        if self.start not in ("reference", "rest"):
            raise InputError(f"start must be 'reference' or 'rest', got {self.start!r}")
        bad = [o for o in self.observers if o not in BATCH_OBSERVERS]
        if not self.observers or bad:
            raise InputError(
                f"sweep observers must be among {', '.join(BATCH_OBSERVERS)}, got {self.observers}"
            )


def box_bounds(
    params: BoucWenParams, half_widths: Mapping[str, tuple[str, float]]
) -> dict[str, tuple[float, float]]:
    """``{name: (lo, hi)}`` from ``{name: ("rel" | "abs", half-width)}``.

    Raises
    ------
    InputError
        Unknown parameter, negative or non-finite half-width.
    UnboundedModelError
        A corner of the box leaves the bounded class (alpha > 0, beta + gamma > 0,
        beta - gamma >= 0 are linear in the parameters, so the corners decide).
    """
    out = {}
    for name, (kind, w) in half_widths.items():
        if name not in MODEL_FIELDS:
            raise InputError(f"unknown parameter {name!r}; uncertain parameters: {MODEL_FIELDS}")
        if not (isinstance(w, int | float) and math.isfinite(w) and w >= 0):
            raise InputError(f"half-width of {name} must be a finite number >= 0, got {w!r}")
        nominal = getattr(params, name)
        half = abs(nominal) * w if kind == "rel" else w
        out[name] = (nominal - half, nominal + half)
    return check_box(params, out)


def check_box(
    params: BoucWenParams, bounds: Mapping[str, tuple[float, float]]
) -> dict[str, tuple[float, float]]:
    """``bounds`` as a dict, after checking that every corner of the box is a usable plant.

    Raises
    ------
    InputError
        A gain parameter (a1, a2, a3) can reach 0 or below.
    UnboundedModelError
        A corner leaves the bounded class.
    """
    for name in ("a1", "a2", "a3"):
        if name in bounds and bounds[name][0] <= 0:
            raise InputError(f"the box lets {name} reach {bounds[name][0]:g}; it must stay > 0")
    lo = {k: bounds.get(k, (getattr(params, k),) * 2)[0] for k in ("alpha", "beta", "gamma")}
    hi = {k: bounds.get(k, (getattr(params, k),) * 2)[1] for k in ("alpha", "beta", "gamma")}
    worst = {
        "alpha > 0": lo["alpha"],
        "beta + gamma > 0": lo["beta"] + lo["gamma"],
        "beta - gamma >= 0": lo["beta"] - hi["gamma"],
    }
    for cond, value in worst.items():
        if value < 0 or (value == 0 and ">=" not in cond):
            raise UnboundedModelError(
                f"the uncertainty box leaves the bounded class: at its worst corner {cond} "
                f"is {value:.6g}; narrow the box"
            )
    return {k: (float(lo_), float(hi_)) for k, (lo_, hi_) in bounds.items()}


def draw_scenarios(
    params: BoucWenParams,
    bounds: Mapping[str, tuple[float, float]],
    n: int,
    *,
    seed: int = 0,
    distribution: str = "uniform",
    level: float = 0.95,
) -> dict[str, np.ndarray]:
    """Draw ``n`` scenarios: columns ``scenario``, the six parameters, ``noise_seed``.

    ``uniform``: independent uniform in ``bounds``. ``normal``: independent normal
    around the nominal value with the half-width as the ``level`` interval
    (sigma = half-width / z), truncated to the box (inverse-CDF sampling, so one
    uniform number per parameter and scenario as for ``uniform``).
    """
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n <= 0:
        raise InputError(f"the number of samples must be an integer > 0, got {n!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed must be an integer >= 0, got {seed!r}")
    if distribution not in DISTRIBUTIONS:
        raise InputError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")
    if not 0 < level < 1:
        raise InputError(f"level must be in (0, 1), got {level!r}")
    check_box(params, bounds)
    rng = np.random.default_rng(int(seed))
    cols: dict[str, np.ndarray] = {"scenario": np.arange(int(n), dtype=np.int64)}
    nd = NormalDist()
    z = nd.inv_cdf(0.5 + level / 2)
    for name in MODEL_FIELDS:  # fixed order: the stream does not depend on dict order
        v = rng.random(int(n))
        nominal = getattr(params, name)
        if name not in bounds:
            cols[name] = np.full(int(n), nominal)
            continue
        lo, hi = bounds[name]
        if distribution == "uniform":
            cols[name] = lo + (hi - lo) * v
        else:
            half = (hi - lo) / 2
            p_lo, p_hi = nd.cdf(-z), nd.cdf(z)
            q = np.array([nd.inv_cdf(p_lo + (p_hi - p_lo) * x) for x in v])
            cols[name] = np.clip(nominal + (half / z) * q if half > 0 else nominal, lo, hi)
    cols["noise_seed"] = rng.integers(0, 2**63 - 1, int(n), dtype=np.int64)
    return cols


def _true_params(params: BoucWenParams, cols: Mapping[str, np.ndarray]) -> list[BoucWenParams]:
    n = len(cols["scenario"])
    return [
        replace(
            params,
            name=f"{params.name}#{int(cols['scenario'][i])}",
            **{k: float(cols[k][i]) for k in MODEL_FIELDS},
        )
        for i in range(n)
    ]


def run_chunk(spec: SweepSpec, cols: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Run one chunk of scenarios for every observer of ``spec``: one row per pair."""
    tps = _true_params(spec.params, cols)
    init = start_on_reference(spec.params, spec.reference) if spec.start == "reference" else {}
    out: dict[str, list[np.ndarray]] = {}
    for obs in spec.observers:
        res = simulate_batch(
            spec.params,
            spec.reference,
            tps,
            dt=spec.dt,
            duration=spec.duration,
            controller=spec.controller,
            observer=obs,
            gains=spec.gains_for(obs),
            noise_std=spec.noise_std,
            seeds=cols["noise_seed"],
            delay=spec.delay,
            **init,
        )
        n = len(res)
        part = {k: np.asarray(cols[k]) for k in ("scenario", *MODEL_FIELDS, "noise_seed")}
        part["observer"] = np.array([obs] * n, dtype=object)
        part.update(maxe=res.maxe, me=res.me, rmse=res.rmse)
        for i in range(3):
            part[f"est_rmse_x{i + 1}"] = res.estimation_rmse[:, i]
        part["stable"] = res.stable
        part["status"] = np.array(res.status, dtype=object)
        for k, v in part.items():
            out.setdefault(k, []).append(v)
    return {k: np.concatenate(v) for k, v in out.items()}


def _chunks(n: int, size: int) -> list[slice]:
    return [slice(i, min(i + size, n)) for i in range(0, n, size)]


def _ordered(parts: Sequence[dict[str, np.ndarray]], observers: Sequence[str]) -> dict:
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    rank = {o: i for i, o in enumerate(observers)}
    order = np.lexsort((np.array([rank[o] for o in cols["observer"]]), cols["scenario"]))
    return {k: v[order] for k, v in cols.items()}


def run_sweep(
    spec: SweepSpec,
    scenarios: Mapping[str, np.ndarray],
    *,
    chunk_size: int = 500,
    workers: int | None = None,
    scheduler: str | None = None,
    retries: int = 2,
    timeout: float = 10.0,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, np.ndarray]:
    """Run every scenario for every observer; columns in scenario order.

    Parameters
    ----------
    spec : SweepSpec
    scenarios : dict of arrays
        From :func:`draw_scenarios`.
    chunk_size : int
        Scenarios per task.
    workers : int, optional
        ``0``: in this process, no Dask. ``K >= 1``: a LocalCluster of ``K``
        worker processes (default: the number of CPUs). Ignored with ``scheduler``.
    scheduler : str, optional
        Address of a running ``dask.distributed`` scheduler.
    retries : int
        Retries of a failed chunk before the sweep fails.
    timeout : float
        Seconds to wait for the scheduler to answer.
    progress : callable, optional
        ``progress(done, total)`` after every chunk.

    Raises
    ------
    SweepError
        A chunk failed after its retries, or the scheduler did not answer.
    """
    n = len(scenarios["scenario"])
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size <= 0:
        raise InputError(f"chunk_size must be an integer > 0, got {chunk_size!r}")
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 0
    ):
        raise InputError(f"workers must be an integer >= 0, got {workers!r}")
    slices = _chunks(n, chunk_size)
    pieces = [{k: np.asarray(v)[s] for k, v in scenarios.items()} for s in slices]
    total = len(pieces)
    if scheduler is None and workers == 0:
        parts = []
        for i, piece in enumerate(pieces):
            parts.append(_attempt(spec, piece, retries, slices[i]))
            if progress:
                progress(i + 1, total)
        return _ordered(parts, spec.observers)
    return _ordered(
        _run_dask(spec, pieces, slices, workers, scheduler, retries, timeout, progress),
        spec.observers,
    )


def _attempt(spec, piece, retries, where):
    for attempt in range(retries + 1):
        try:
            return run_chunk(spec, piece)
        except BWDesignError:
            raise
        except Exception as err:  # noqa: BLE001 - reported with the chunk after the retries
            if attempt == retries:
                raise SweepError(
                    f"chunk of scenarios {where.start}..{where.stop - 1} failed after "
                    f"{retries} retries: {type(err).__name__}: {err}"
                ) from None
    raise AssertionError("unreachable")


def _run_dask(spec, pieces, slices, workers, scheduler, retries, timeout, progress):
    require("dask.distributed", extra="sweep", feature="a sweep on Dask (--workers 0 runs here)")
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    try:
        if scheduler is not None:
            try:
                client = Client(scheduler, timeout=timeout)
            except (OSError, TimeoutError) as err:
                raise SweepError(
                    f"no Dask scheduler answered at {scheduler!r} within {timeout:g} s ({err})"
                ) from None
        else:
            try:
                # the workers never see a Ctrl-C at the terminal (this process closes
                # them); one during the start is raised once the cluster exists
                with interrupts.deferred():
                    cluster = LocalCluster(
                        n_workers=workers or os.cpu_count() or 1,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=":0",
                        silence_logs=logging.ERROR,
                    )
            except Exception as err:  # noqa: BLE001 - no cluster: say so, no traceback
                raise SweepError(
                    f"could not start a local Dask cluster ({type(err).__name__}: {err}); "
                    "--workers 0 runs the sweep in this process"
                ) from None
            client = Client(cluster)
        with client:
            futures = {
                client.submit(run_chunk, spec, piece, retries=retries, pure=False): i
                for i, piece in enumerate(pieces)
            }
            parts: list[Any] = [None] * len(pieces)
            failed = []
            for done, fut in enumerate(as_completed(futures), start=1):
                i = futures[fut]
                try:
                    parts[i] = fut.result()
                except BWDesignError:
                    raise
                except Exception as err:  # noqa: BLE001 - reported below, never dropped
                    failed.append(f"{slices[i].start}..{slices[i].stop - 1} ({err})")
                if progress:
                    progress(done, len(pieces))
            if failed:
                raise SweepError(
                    f"{len(failed)} chunk(s) failed after {retries} retries: scenarios "
                    + "; ".join(failed)
                )
            return parts
    finally:
        if cluster is not None:
            cluster.close()


def spec_from_config(
    config: Any,
    *,
    tuning: str = "config",
    form: str = "continuous",
    observers: Sequence[str] = ("phso", "eso"),
    noise_std: float = 0.0,
    duration: float | None = None,
    delay: bool = False,
    start: str = "reference",
) -> SweepSpec:
    """The sweep of a stage's loop: ``tuning="config"`` runs the ``[observer]`` gains and
    ``[controller]`` constants (eq. 12 in ``form``), ``"digital"`` the digital tuning
    (:func:`bwdesign.digital_tuning`); ``[controller]`` limits apply in both. ``duration``
    defaults to three reference periods, at least 1 s.
    """
    from ..control.controllers import make_controller
    from ..control.tuning import digital_tuning
    from ..errors import ConfigError

    if tuning not in ("config", "digital"):
        raise InputError(f"tuning must be 'config' or 'digital', got {tuning!r}")
    missing = [
        s for s, v in (("[sampling] dt", config.dt), ("[reference]", config.reference)) if v is None
    ]
    if tuning == "config":
        if config.gains is None:
            missing.append("[observer] gains (or the digital tuning)")
        if config.controller is None:
            missing.append("[controller] (or the digital tuning)")
    if missing:
        raise ConfigError(f"{config.source or 'config'}: a sweep needs {', '.join(missing)}")
    params, dt, ctl = config.plant, config.dt, config.controller
    limits = None
    if ctl is not None and (ctl.u_min is not None or ctl.u_max is not None):
        limits = (
            -math.inf if ctl.u_min is None else ctl.u_min,
            math.inf if ctl.u_max is None else ctl.u_max,
        )
    if tuning == "digital":
        tune = digital_tuning(params, dt)
        gains = tuple(tune.gains)
        controller = make_controller(
            params,
            tune.lambda1,
            tune.lambda2,
            form="discrete",
            dt=dt,
            integral_rate=tune.integral_rate,
            u_limits=limits,
        )
    else:
        gains = tuple(config.gains)
        controller = make_controller(
            params, ctl.lambda1, ctl.lambda2, form=form, dt=dt, u_limits=limits
        )
    period = config.reference.period
    duration = duration or max(1.0, 3 * period if period else 1.0)
    return SweepSpec(
        params=params,
        reference=config.reference,
        dt=dt,
        duration=duration,
        controller=controller,
        gains=gains,
        observers=tuple(observers),
        noise_std=noise_std,
        delay=delay,
        start=start,
    )


def bounds_from_config(config: Any) -> dict[str, tuple[float, float]]:
    """The box of the stage's ``[uncertainty]`` section (its uncertain parameters only)."""
    from ..errors import ConfigError

    box = getattr(config, "uncertainty", None)
    if box is None:
        raise ConfigError(
            f"{config.source or 'config'}: no [uncertainty] section to draw the scenarios "
            "from (bwdesign sweep also takes --uncertainty)"
        )
    b = box.bounds(config.plant)
    open_ = [k for k, (lo, hi) in b.items() if not (math.isfinite(lo) and math.isfinite(hi))]
    if open_:
        raise ConfigError(
            f"{config.source or 'config'}: [uncertainty] leaves {', '.join(open_)} undetermined "
            "(infinite half-width); a sweep needs a finite box (finite half-widths, or "
            "bwdesign sweep --uncertainty)"
        )
    return check_box(config.plant, {k: v for k, v in b.items() if v[0] != v[1]})
