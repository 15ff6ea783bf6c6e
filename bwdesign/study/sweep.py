"""The study's Monte Carlo sweep over ``[uncertainty]`` and the statistics of a sweep's table.

:func:`sweep_summary` is the summary of any sweep table (``bwdesign sweep`` writes it
as ``summary.json``); :func:`stage_sweep` runs the small sweep a stage's ``[sweep]``
section asks for, in this process (no Dask).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..design.tuning import stage_tuning
from ..errors import ConfigError, InputError
from ..model.config import StageConfig
from ..sim.sweep import check_samples, draw_scenarios, run_sweep, spec_from_config, sweep_box
from .result import SweepStudy

__all__ = ["sweep_summary", "stage_sweep", "check_stage_sweep", "QUANTILES"]

QUANTILES = (0.5, 0.9, 0.99)


def sweep_summary(
    table: Mapping[str, np.ndarray], *, udot_max: float | None = None
) -> dict[str, Any]:
    """Per observer: scenario count, fraction unstable, quantiles and max of each metric.

    With the envelope ``udot_max`` the loop's certificate assumed and the table's
    ``within_envelope`` column: ``outside_envelope`` (stable scenarios whose input
    rate left it), its fraction of all scenarios and ``worst_envelope_ratio``
    (largest ``input_rate_max / udot_max``); None without an envelope.
    """
    out: dict[str, Any] = {}
    for obs in dict.fromkeys(table["observer"].tolist()):
        sel = table["observer"] == obs
        stable = table["stable"][sel]
        doc: dict[str, Any] = {
            "scenarios": int(sel.sum()),
            "unstable": int((~stable).sum()),
            "fraction_unstable": float((~stable).mean()),
        }
        doc.update(_envelope_summary(table, sel, udot_max))
        for m in ("me", "maxe", "rmse"):
            v = table[m][sel][stable]
            doc[m] = (
                {f"p{round(q * 100)}": float(np.quantile(v, q)) for q in QUANTILES}
                | {
                    "max": float(v.max()),
                    "worst_scenario": int(table["scenario"][sel][stable][v.argmax()]),
                }
                if v.size
                else None
            )
        out[obs] = doc
    return out


def _envelope_summary(
    table: Mapping[str, np.ndarray], sel: np.ndarray, udot_max: float | None
) -> dict[str, Any]:
    stable = table["stable"][sel]
    rates = table["input_rate_max"][sel][stable] if "input_rate_max" in table else np.array([])
    doc: dict[str, Any] = {
        "input_rate_max": (
            {
                "max": float(rates.max()),
                "worst_scenario": int(table["scenario"][sel][stable][rates.argmax()]),
            }
            if rates.size
            else None
        ),
        "udot_max": udot_max,
        "outside_envelope": None,
        "fraction_outside_envelope": None,
        "worst_envelope_ratio": None,
    }
    if udot_max is not None and "within_envelope" in table:
        outside = stable & ~table["within_envelope"][sel]
        doc["outside_envelope"] = int(outside.sum())
        doc["fraction_outside_envelope"] = float(outside.mean())
        doc["worst_envelope_ratio"] = float(rates.max() / udot_max) if rates.size else None
    return doc


def check_stage_sweep(config: StageConfig) -> None:
    """The ``[sweep]`` section can run: a finite ``[uncertainty]`` box, a sample count in range."""
    sweep_box(config)  # [sweep] needs a usable [uncertainty] box: say so now
    try:
        check_samples(config.sweep["samples"], len(config.sweep["observers"]))
    except InputError as err:
        raise ConfigError(f"{config.source or 'config'}: [sweep] samples: {err}") from None


def stage_sweep(config: StageConfig) -> SweepStudy:
    """The sweep of ``[sweep]`` over ``[uncertainty]``, run in this process (no Dask)."""
    cfg = config.sweep
    tuning = cfg.get("tuning", "config")
    spec = spec_from_config(
        config,
        law=stage_tuning(config, tuning),
        observers=cfg.get("observers", ("phso", "eso")),
        noise_std=cfg.get("noise_std_um", 0.0),
        duration=cfg.get("duration_s"),
    )
    bounds = spec.box.check(spec.params)
    seed, n = cfg.get("seed", 0), cfg["samples"]
    dist = cfg.get("distribution", "uniform")
    scenarios = draw_scenarios(spec.params, spec.box, n, seed=seed, distribution=dist)
    table = run_sweep(spec, scenarios, chunk_size=n, workers=0)
    return SweepStudy(
        spec=spec,
        tuning=tuning,
        bounds=bounds,
        samples=n,
        seed=seed,
        distribution=dist,
        table=table,
        summary=sweep_summary(table, udot_max=spec.udot_max),
    )
