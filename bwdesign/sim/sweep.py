"""Monte Carlo sweeps: scenarios drawn from an uncertainty box, run in chunks, locally or on Dask.

- The box is a :class:`~bwdesign.UncertaintyBox` (the stage's ``[uncertainty]``, or
  ``bwdesign sweep --uncertainty``: :func:`sweep_box`), held by the :class:`SweepSpec`
  and checked against its parameters (:meth:`~bwdesign.UncertaintyBox.check`).
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
- Every row records the largest input rate ``input_rate_max`` over the metrics
  window and, when the spec names the envelope its certificate assumed
  (``SweepSpec.udot_max``), whether it stayed inside (``within_envelope``).
  A certificate says nothing about a row outside it.
- The limits are checked before any work: :func:`check_samples` (memory),
  :func:`check_workers` (local cluster size), :func:`check_scheduler` (address
  form) and :func:`check_observers` (each observer once).

This module is the only one that imports dask (inside functions).
"""

from __future__ import annotations

import functools
import logging
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from statistics import NormalDist
from typing import Any

import numpy as np

from .. import interrupts
from ..control.baseline_tuning import make_baseline
from ..control.loop import ON_REFERENCE, ClosedLoop, Start
from ..errors import BWDesignError, ConfigError, InputError, SweepError
from ..extras import require
from ..model.config import BASELINE_KINDS
from ..model.params import MODEL_FIELDS, BoucWenParams
from ..model.references import Reference
from ..model.uncertainty import DisturbanceBound, UncertaintyBox
from ..observers.gains import gains_for_observer
from ..observers.spec import ObserverSpec
from ..validate import UDOT_MAX, Range, integer, real
from .batch import BATCH_OBSERVERS, simulate_batch

__all__ = [
    "SweepSpec",
    "scenario_disturbance",
    "SweepError",
    "METRIC_COLUMNS",
    "draw_scenarios",
    "run_chunk",
    "run_sweep",
    "spec_from_config",
    "sweep_box",
    "check_samples",
    "check_workers",
    "check_scheduler",
    "check_observers",
    "max_samples",
    "max_workers",
    "WORKERS_PER_CPU",
    "ROW_BYTES",
    "MEMORY_CAP",
]

DISTRIBUTIONS = ("uniform", "normal")
#: Result columns per (scenario, observer) row, after the drawn ones.
METRIC_COLUMNS = (
    "maxe",
    "me",
    "rmse",
    "est_rmse_x1",
    "est_rmse_x2",
    "est_rmse_x3",
    "input_rate_max",
)
#: Local Dask worker processes per CPU at most: the chunks are CPU-bound, so more
#: processes only queue on the same cores (and each costs ~100 MB and a start-up).
WORKERS_PER_CPU = 2
#: Peak memory per (scenario, observer) row of a sweep, in bytes: the growth of the
#: peak resident size of ``bwdesign sweep`` (two observers, --workers 0) from 50 000 to
#: 200 000 scenarios, 433 bytes per row (drawn columns, chunk results, the ordered
#: table, the Parquet copy), rounded up.
ROW_BYTES = 440
#: A sweep plans for at most half the machine's memory and never more than this.
MEMORY_CAP = 8 * 2**30
_ADDRESS = re.compile(
    r"(?:(?P<scheme>tcp|tls)://)?(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?)"
    r":(?P<port>[0-9]{1,5})/?"
)


@dataclass(frozen=True)
class SweepSpec:
    """What every scenario shares: the loop and the run (picklable for Dask).

    Attributes
    ----------
    loop : ClosedLoop
        The model, the law (with its limits), dt, the delay and the start; its observer
        is replaced per run by each of ``observers`` on ``gains``.
    reference : Reference
    duration : float
        Run length (s).
    gains : tuple of 3 floats
        The observer design (the PHDO runs ``(l1, l2, 0, l3)`` of it).
    observers : tuple of str
        Observers run on every scenario (``"phso"``, ``"eso"``, ``"phdo"``), or baselines
        (``"pi"``, ``"pid"``, ``"pi-bwff"``, ``"pi-piff"``: no observer, the law replaced by
        the baseline tuned for the model, dt and delay, with the law's input limits).
    noise_std : float
        Sensor noise std (length unit).
    udot_max : float, optional
        The input-rate envelope ``|u'| <= udot_max`` (input unit/s) the loop's certificate
        assumed; each row then says whether its input stayed inside
        (``within_envelope``). None: rates are recorded, not compared.
    envelope_source : str
        Where ``udot_max`` comes from, for reports.
    box : UncertaintyBox
        The box the scenarios are drawn from (:func:`draw_scenarios`); checked
        against ``params`` here (:meth:`UncertaintyBox.check`). Default: empty,
        every parameter exact.
    disturbance : DisturbanceBound, optional
        An input disturbance on every scenario's plant (the stage's
        ``[uncertainty.disturbance]``): scenario ``i`` runs
        :func:`scenario_disturbance` seeded by its ``noise_seed``. None: none.
    """

    loop: ClosedLoop
    reference: Reference
    duration: float
    gains: tuple[float, float, float]
    observers: tuple[str, ...] = ("phso",)
    noise_std: float = 0.0
    udot_max: float | None = None
    envelope_source: str = ""
    box: UncertaintyBox = field(default_factory=UncertaintyBox)
    disturbance: DisturbanceBound | None = None

    def loop_for(self, observer: str) -> ClosedLoop:
        """The loop with ``observer`` on the design gains (the PHDO on ``(l1, l2, 0, l3)``),
        or the baseline of that name (no observer)."""
        if observer in BASELINE_KINDS:
            lim = self.controller.u_limits
            ctrl = _baseline(
                self.params, self.dt, observer, self.reference, self.delay, lim,
                self.loop.allow_unbounded,
            )  # fmt: skip
            return self.loop.replace(observer=None, controller=ctrl)
        return self.loop.replace(observer=ObserverSpec.of(observer, self.gains))

    def gains_for(self, observer: str) -> tuple[float, ...]:
        """The continuous gains ``observer`` runs: ``gains``; ``(l1, l2, 0, l3)`` for the PHDO."""
        return gains_for_observer(observer, self.gains)

    @property
    def params(self) -> BoucWenParams:
        """The model of the observer and the controller."""
        return self.loop.model

    @property
    def dt(self) -> float:
        return self.loop.dt

    @property
    def controller(self) -> Any:
        return self.loop.controller

    @property
    def delay(self) -> bool:
        return self.loop.delay

    @property
    def start(self) -> str:
        """``"reference"`` or ``"rest"``."""
        return "reference" if self.loop.start == ON_REFERENCE else "rest"

    def __post_init__(self) -> None:
        if not isinstance(self.loop, ClosedLoop):
            raise InputError(f"loop must be a ClosedLoop, got {self.loop!r}")
        check_observers(self.observers)
        if self.udot_max is not None:
            real(self.udot_max, "udot_max (input unit/s)", within=UDOT_MAX)
        if not isinstance(self.box, UncertaintyBox):
            raise InputError(f"box must be an UncertaintyBox, got {self.box!r}")
        self.box.check(self.params)
        if self.disturbance is not None and not isinstance(self.disturbance, DisturbanceBound):
            raise InputError(f"disturbance must be a DisturbanceBound, got {self.disturbance!r}")


@functools.lru_cache(maxsize=32)
def _baseline(params, dt, kind, reference, delay, limits, unbounded) -> Any:
    """The sweep's baseline (tuned, its Prandtl-Ishlinskii fit made once per process)."""
    return make_baseline(
        params, dt, kind, reference=reference, delay=delay, u_limits=limits,
        allow_unbounded=unbounded,
    )  # fmt: skip


#: What a sweep runs per scenario: the batched observers and the baselines.
SWEEP_LOOPS = (*BATCH_OBSERVERS, *BASELINE_KINDS)


def check_observers(observers: Sequence[str]) -> tuple[str, ...]:
    """``observers`` as a tuple: each among :data:`SWEEP_LOOPS`, each once.

    Raises
    ------
    InputError
        None given, an unknown name, or a name given twice (it would count every
        scenario twice).
    """
    obs = tuple(observers)
    bad = [o for o in obs if o not in SWEEP_LOOPS]
    if not obs or bad:
        raise InputError(f"sweep observers must be among {', '.join(SWEEP_LOOPS)}, got {obs}")
    twice = sorted({o for o in obs if obs.count(o) > 1})
    if twice:
        raise InputError(
            f"sweep observers must each be given once: {', '.join(twice)} given "
            f"{max(obs.count(o) for o in twice)} times (every scenario would count twice)"
        )
    return obs


def max_workers() -> int:
    """Most local worker processes a sweep starts: :data:`WORKERS_PER_CPU` per CPU."""
    return WORKERS_PER_CPU * (os.cpu_count() or 1)


def check_workers(workers: Any) -> int | None:
    """``workers`` (None, 0 or a local cluster's size) after checking it fits this machine.

    Raises
    ------
    InputError
        Not an integer >= 0, or more than :func:`max_workers`.
    """
    if workers is None:
        return None
    n = integer(workers, "workers", within=Range(0, math.inf))
    limit = max_workers()
    if n > limit:
        raise InputError(
            f"workers = {n} is more than a local cluster can run here: at most {limit} worker "
            f"processes ({WORKERS_PER_CPU} per CPU, {os.cpu_count() or 1} CPU(s)); "
            "a larger cluster runs elsewhere (--scheduler)"
        )
    return n


def check_scheduler(address: Any) -> str | None:
    """``address`` of a dask scheduler after checking its form ``[tcp|tls://]HOST:PORT``.

    Raises
    ------
    InputError
        Not a string of that form, or a port outside 1..65535.
    """
    if address is None:
        return None
    m = _ADDRESS.fullmatch(address.strip()) if isinstance(address, str) else None
    if m is None or not 1 <= int(m["port"]) <= 65535:
        raise InputError(
            f"scheduler address {address!r} is not of the form tcp://HOST:PORT "
            "(or tls://HOST:PORT, or HOST:PORT; PORT in 1..65535)"
        )
    return address.strip()


def _memory() -> tuple[int, str]:
    """Bytes a sweep may plan for, and why."""
    try:
        total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        total = 0
    cap = f"{MEMORY_CAP / 2**30:g} GiB"
    if total <= 0:
        return MEMORY_CAP, f"this machine's memory is unknown: the cap of {cap}"
    half = f"half of this machine's {total / 2**30:.3g} GiB"
    if total // 2 < MEMORY_CAP:
        return total // 2, half
    return MEMORY_CAP, f"{half}, capped at {cap}"


def max_samples(n_observers: int = 1) -> int:
    """Most scenarios one sweep holds with ``n_observers`` observers.

    The memory a sweep plans for (half the machine's, at most :data:`MEMORY_CAP`)
    over :data:`ROW_BYTES` per (scenario, observer) row.
    """
    k = integer(n_observers, "number of observers", within=Range(1, math.inf))
    return _memory()[0] // (ROW_BYTES * k)


def check_samples(n: Any, n_observers: int = 1) -> int:
    """``n`` scenarios after checking they fit in memory with ``n_observers`` observers.

    Raises
    ------
    InputError
        Not an integer > 0, or more than :func:`max_samples`.
    """
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n <= 0:
        raise InputError(f"the number of samples must be an integer > 0, got {n!r}")
    n = int(n)
    limit = max_samples(n_observers)
    if n > limit:
        budget, why = _memory()
        need = n * n_observers * ROW_BYTES
        raise InputError(
            f"{n} scenarios x {n_observers} observer(s) need about {need / 2**30:.3g} GiB "
            f"({ROW_BYTES} bytes per row); a sweep plans for at most {budget / 2**30:.3g} GiB "
            f"({why}): at most {limit} scenarios with {n_observers} observer(s). "
            "Run a larger study as several sweeps with different seeds"
        )
    return n


def draw_scenarios(
    params: BoucWenParams,
    box: UncertaintyBox,
    n: int,
    *,
    seed: int = 0,
    distribution: str = "uniform",
    level: float = 0.95,
) -> dict[str, np.ndarray]:
    """Draw ``n`` scenarios: columns ``scenario``, the six parameters, ``noise_seed``.

    ``uniform``: independent uniform in the box around ``params``. ``normal``:
    independent normal around the nominal value with the half-width as the ``level``
    interval (sigma = half-width / z), truncated to the box (inverse-CDF sampling, so
    one uniform number per parameter and scenario as for ``uniform``). A parameter the
    box does not vary keeps its nominal value.

    Raises
    ------
    InputError
        Bad ``n``, ``seed``, ``distribution`` or ``level``; ``box`` not an
        :class:`UncertaintyBox`.
    ParameterError
        A corner of the box is not a usable plant (:meth:`UncertaintyBox.check`).
    """
    check_samples(n)
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed must be an integer >= 0, got {seed!r}")
    if distribution not in DISTRIBUTIONS:
        raise InputError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")
    if not 0 < level < 1:
        raise InputError(f"level must be in (0, 1), got {level!r}")
    if not isinstance(box, UncertaintyBox):
        raise InputError(f"box must be an UncertaintyBox, got {box!r}")
    bounds = box.check(params)
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


def scenario_disturbance(bound: DisturbanceBound, seeds: Any, t: np.ndarray) -> np.ndarray:
    """Seeded slowly varying input disturbances within ``bound``, one row per seed.

    ``d_i(t) = input_max sin(2 pi f_i t + phi_i)`` with ``f_i`` uniform in ``[0,
    rate_max / (2 pi input_max)]`` (so ``|d'| <= rate_max``) and ``phi_i`` uniform in
    ``[0, 2 pi)``, drawn from ``numpy.random.default_rng([seed, 26])`` (a stream apart
    from the scenario's noise). ``rate_max = 0`` gives a constant in ``[-input_max,
    input_max]``.
    """
    t = np.asarray(t, dtype=float)
    rows = np.zeros((len(seeds), t.size))
    dm = bound.input_max
    if dm == 0:
        return rows
    wmax = bound.rate_max / dm
    for i, seed in enumerate(seeds):
        u = np.random.default_rng([int(seed), 26]).random(2)
        rows[i] = dm * np.sin(wmax * u[0] * t + 2 * np.pi * u[1])
    return rows


def run_chunk(spec: SweepSpec, cols: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Run one chunk of scenarios for every observer of ``spec``: one row per pair.

    Columns: the drawn ones, ``observer``, :data:`METRIC_COLUMNS` (metrics over the
    steady-state window; ``input_rate_max`` is the largest ``|u_k - u_(k-1)| / dt``
    there), ``stable``, ``within_envelope`` (stable with ``input_rate_max <=
    spec.udot_max``; only when the spec names an envelope) and ``status``.
    """
    tps = _true_params(spec.params, cols)
    dist = None
    if spec.disturbance is not None and not spec.disturbance.none:
        t = np.arange(int(round(spec.duration / spec.dt))) * spec.dt
        dist = scenario_disturbance(spec.disturbance, cols["noise_seed"], t)
    out: dict[str, list[np.ndarray]] = {}
    for obs in spec.observers:
        res = simulate_batch(
            spec.loop_for(obs),
            spec.reference,
            tps,
            duration=spec.duration,
            noise_std=spec.noise_std,
            seeds=cols["noise_seed"],
            input_disturbance=dist,
        )
        n = len(res)
        part = {k: np.asarray(cols[k]) for k in ("scenario", *MODEL_FIELDS, "noise_seed")}
        part["observer"] = np.array([obs] * n, dtype=object)
        part.update(maxe=res.maxe, me=res.me, rmse=res.rmse)
        for i in range(3):
            part[f"est_rmse_x{i + 1}"] = res.estimation_rmse[:, i]
        part["input_rate_max"] = res.input_rate_max
        part["stable"] = res.stable
        if spec.udot_max is not None:
            with np.errstate(invalid="ignore"):
                part["within_envelope"] = res.stable & (res.input_rate_max <= spec.udot_max)
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
        worker processes (default: the number of CPUs; at most :func:`max_workers`).
        Ignored with ``scheduler``.
    scheduler : str, optional
        Address of a running ``dask.distributed`` scheduler (``tcp://HOST:PORT``).
    retries : int
        Retries of a failed chunk before the sweep fails.
    timeout : float
        Seconds to wait for the scheduler to answer.
    progress : callable, optional
        ``progress(done, total)`` after every chunk.

    Raises
    ------
    InputError
        More scenarios than :func:`max_samples`, more workers than :func:`max_workers`,
        a malformed scheduler address, a bad chunk size.
    SweepError
        A chunk failed after its retries, or the scheduler did not answer.
    """
    n = check_samples(len(scenarios["scenario"]), len(spec.observers))
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size <= 0:
        raise InputError(f"chunk_size must be an integer > 0, got {chunk_size!r}")
    workers = check_workers(workers)
    scheduler = check_scheduler(scheduler)
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
            except (TypeError, ValueError) as err:  # e.g. tls:// without a TLS configuration
                raise SweepError(
                    f"could not connect to the Dask scheduler at {scheduler!r} "
                    f"({type(err).__name__}: {err})"
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
            # the spec (loops, reference, box) goes to every worker once, not with each chunk
            shared = client.scatter(spec, broadcast=True, hash=False)
            futures = {
                client.submit(run_chunk, shared, piece, retries=retries, pure=False): i
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
    law: Any = None,
    form: str = "continuous",
    observers: Sequence[str] = ("phso", "eso"),
    noise_std: float = 0.0,
    duration: float | None = None,
    delay: bool = False,
    start: str = "reference",
    uncertainty: UncertaintyBox | None = None,
) -> SweepSpec:
    """The sweep of a stage's loop: without ``law`` the ``[observer]`` gains and
    ``[controller]`` constants (eq. 12 in ``form``), else the tuned law its caller chose
    (a :class:`bwdesign.DigitalTuning`, e.g. :func:`bwdesign.design.stage_tuning`: the
    sweep simulates gains, it does not choose them); ``[controller]`` limits apply in
    both. ``duration`` defaults to three reference periods, at least 1 s. ``udot_max`` is
    the stage's ``[envelope]`` (the one its certificates assume), else the envelope the
    reference itself needs (:func:`bwdesign.derive_envelope`, margin 1). The box is
    ``uncertainty``, else the stage's ``[uncertainty]`` (:func:`sweep_box`).
    """
    missing = [
        s for s, v in (("[sampling] dt", config.dt), ("[reference]", config.reference)) if v is None
    ]
    if law is None:
        if config.gains is None:
            missing.append("[observer] gains (or the digital tuning)")
        if config.controller is None:
            missing.append("[controller] (or the digital tuning)")
    if missing:
        raise ConfigError(f"{config.source or 'config'}: a sweep needs {', '.join(missing)}")
    box = sweep_box(config, uncertainty)
    if start not in ("reference", "rest"):
        raise InputError(f"start must be 'reference' or 'rest', got {start!r}")
    gains = tuple(float(g) for g in (law.gains if law is not None else config.gains))
    loop = ClosedLoop.from_config(
        config,
        gains=gains,
        law=law,
        form=form,
        start=ON_REFERENCE if start == "reference" else Start(),
    ).replace(delay=delay)
    period = config.reference.period
    duration = duration or max(1.0, 3 * period if period else 1.0)
    udot_max, source = _stage_envelope(config)
    return SweepSpec(
        loop=loop,
        reference=config.reference,
        duration=duration,
        gains=gains,
        observers=tuple(observers),
        noise_std=noise_std,
        udot_max=udot_max,
        envelope_source=source,
        box=box,
        disturbance=getattr(config, "disturbance", None),
    )


def _stage_envelope(config: Any) -> tuple[float | None, str]:
    """The envelope the stage's certificates assume: ``[envelope]``, else the reference's own."""
    from ..model.envelope import derive_envelope

    if config.envelope_spec is not None:
        env = config.envelope()
        how = (
            "stated in [envelope]"
            if env.source == "given"
            else f"[envelope]: derived from [reference], margin {env.margin:g}"
        )
        return env.udot_max, how
    try:
        env = derive_envelope(config.plant, config.reference)
    except InputError as err:  # a sharp step has no finite rate: nothing to compare with
        return None, f"none (no [envelope], and {err})"
    return env.udot_max, "derived from [reference] (no [envelope] in the stage; margin 1)"


def sweep_box(config: Any, uncertainty: UncertaintyBox | None = None) -> UncertaintyBox:
    """The box a stage's sweep draws from: ``uncertainty`` (``bwdesign sweep --uncertainty``),
    else the stage's ``[uncertainty]``, after checking it against the stage's plant.

    Raises
    ------
    ConfigError
        Neither is given.
    ParameterError
        A corner of the box is not a usable plant (:meth:`UncertaintyBox.check`).
    """
    box = getattr(config, "uncertainty", None) if uncertainty is None else uncertainty
    if box is None:
        raise ConfigError(
            f"{config.source or 'config'}: no [uncertainty] section to draw the scenarios "
            "from (bwdesign sweep also takes --uncertainty)"
        )
    if not isinstance(box, UncertaintyBox):
        raise InputError(f"uncertainty must be an UncertaintyBox, got {box!r}")
    box.check(config.plant)
    return box
