"""Assertions for a user's pytest suite: certified gains, feasible synthesis, tracking, C export.

Each raises :class:`AssertionError` with a short table of what failed (requirement,
required, achieved, and a line of explanation), and returns the checks when all pass.

Examples
--------
>>> from bwdesign.testing import assert_certified
>>> checks = assert_certified("paper_experiment")          # the bundled stage file
>>> checks[0].value
'sampled'
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from collections.abc import Mapping
from dataclasses import replace
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

from .checks import (
    Check,
    as_stage,
    check_certified,
    check_synthesis,
    check_tracking,
    failure_table,
)

__all__ = [
    "assert_certified",
    "assert_synthesis_feasible",
    "assert_tracks",
    "assert_c_matches_python",
]


def _raise_if_failed(what: str, checks: list[Check]) -> list[Check]:
    __tracebackhide__ = True  # pytest shows the table, not this frame
    if not all(c.passed for c in checks):
        raise AssertionError(f"{what}\n{failure_table(checks)}")
    return checks


def assert_certified(
    stage: Any,
    gains: Any = None,
    *,
    udot_max: float | None = None,
    dt: float | None = None,
    tier: str | None = None,
    decay: float = 0.0,
    uncertainty: Any = None,
) -> list[Check]:
    """The gains are certified at the envelope.

    Parameters
    ----------
    stage : path, preset name, StageConfig or BoucWenParams
    gains : (l1, l2, l3), optional
        Default: the stage's ``[observer]`` gains.
    udot_max : float, optional
        ``|u'|`` bound (V/s); default: the stage's envelope.
    dt : float, optional
        Sample time (s); default ``[sampling] dt`` (adds the sampled tier).
    tier : str, optional
        Require this tier (``"sector"``, ``"sampled"``, ...); default: any tier.
    decay : float
        Required decay rate (1/s).
    uncertainty : UncertaintyBox or mapping, optional
        Also require the certificate at every corner of this box (each corner taken
        as the model): the gains stay certified whatever the identified parameters
        in the box are. A mapping ``{name: (lo, hi)}`` is taken as absolute bounds.
    """
    __tracebackhide__ = True
    config = as_stage(stage)
    checks = [
        check_certified(config, gains=gains, udot_max=udot_max, dt=dt, tier=tier, decay=decay)
    ]
    if uncertainty is not None:
        for corner in _corners(config.plant, uncertainty):
            c = check_certified(
                replace(config, plant=corner),
                gains=gains,
                udot_max=udot_max,
                dt=dt,
                tier=tier,
                decay=decay,
            )
            checks.append(
                Check(c.stage, f"certified@{corner.name}", c.passed, c.value, c.limit, c.text)
            )
    return _raise_if_failed(f"{checks[0].stage}: gains not certified", checks)


def _corners(params, box):
    if hasattr(box, "vertices"):
        return box.vertices(params)
    names = list(box)
    out = []
    for i, combo in enumerate(product(*[box[n] for n in names])):
        out.append(
            replace(params, name=f"corner{i}", **dict(zip(names, map(float, combo), strict=True)))
        )
    return out


def assert_synthesis_feasible(
    stage: Any,
    *,
    udot_max: float,
    decay: float,
    dt: float | None = None,
    pole_radius: float | None = None,
) -> list[Check]:
    """Synthesis finds gains certified for ``udot_max`` (V/s) with ``decay`` (1/s)."""
    __tracebackhide__ = True
    config = as_stage(stage)
    c = check_synthesis(config, udot_max=udot_max, decay=decay, dt=dt, pole_radius=pole_radius)
    return _raise_if_failed(f"{c.stage}: synthesis infeasible", [c])


def assert_tracks(
    stage: Any,
    *,
    max_me: float,
    max_maxe: float | None = None,
    noise_std: float = 0.0,
    mismatch: Mapping[str, float] | None = None,
    observer: str = "phso",
    duration: float | None = None,
    start: str = "reference",
) -> list[Check]:
    """The stage's loop tracks its ``[reference]`` within ``max_me`` (and ``max_maxe``), um.

    ``mismatch``: relative parameter errors of the simulated plant (``{"a1": 0.02}``);
    without it, the worst over the ``[uncertainty]`` corners when the stage has them.
    ``start``: ``"reference"`` (as the report's runs) or ``"rest"``.
    """
    __tracebackhide__ = True
    config = as_stage(stage)
    checks = check_tracking(
        config,
        max_me=max_me,
        max_maxe=max_maxe,
        noise_std=noise_std,
        mismatch=mismatch,
        observer=observer,
        duration=duration,
        start=start,
    )
    return _raise_if_failed(f"{checks[0].stage}: tracking out of bounds", checks)


def assert_c_matches_python(
    stage: Any,
    *,
    precision: str = "float64",
    observer: str = "phso",
    steps: int = 20_000,
    tol: float | None = None,
    compiler: str | None = None,
) -> list[Check]:
    """The exported C observer agrees with the Python class on a seeded record.

    Exports the stage with :func:`bwdesign.export_c`, compiles the harness with the
    system C compiler, runs ``steps`` samples of a sine with minor loops and 10 nm
    noise and compares the posterior with ``batch_filter``, relative to each
    state's range (``tol`` default 1e-12 for float64, 1e-4 for float32).
    ``observer``: ``"phso"``, ``"eso"`` or ``"phdo"``; each runs the gains
    :func:`~bwdesign.export_c` gives it from the stage's ``[observer]`` gains
    (:func:`bwdesign.observers.gains.gains_for_observer`: ``(l1, l2, 0, l3)`` for the PHDO).
    """
    __tracebackhide__ = True
    from ..codegen.export import OBSERVERS, export_c
    from ..model.plant import simulate_zoh
    from ..observers.gains import gains_for_observer

    config = as_stage(stage)
    cc = compiler or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise AssertionError("no C compiler found (install gcc or pass compiler=)")
    tol = tol if tol is not None else (1e-12 if precision == "float64" else 1e-4)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "c"
        export_c(config, out, precision=precision, observer=observer)
        exe = out / "harness"
        subprocess.run(
            [cc, "-std=c99", "-O2", *map(str, sorted(out.glob("*.c"))), "-lm", "-o", str(exe)],
            check=True,
            capture_output=True,
        )
        p, dt = config.plant, config.dt
        t = np.arange(steps) * dt
        u = 60 + 40 * np.sin(2 * np.pi * t) + 5 * np.sin(2 * np.pi * 17 * t)
        z = simulate_zoh(p, u, dt, x0=np.zeros(3))[1:, 0]
        z = z + np.random.default_rng(0).normal(0, 0.01, steps)
        cls = OBSERVERS[observer][0]
        # the gains export-c gives this observer: (l1, l2, 0, l3) for the PHDO
        ref = cls(p, gains_for_observer(observer, config.gains), dt).batch_filter(z, u)
        text = "\n".join(f"{a!r},{b!r}" for a, b in zip(u.tolist(), z.tolist(), strict=True))
        res = subprocess.run(
            [str(exe), observer], input=text, capture_output=True, text=True, check=True
        )
        got = np.loadtxt(res.stdout.splitlines(), delimiter=",", ndmin=2)
    err = float(np.max(np.max(np.abs(got - ref), axis=0) / np.ptp(ref, axis=0)))
    name = Path(config.source).name if config.source else "stage"
    c = Check(
        name,
        f"c_matches_python[{precision}]",
        err <= tol,
        err,
        tol,
        f"{observer.upper()} C vs Python, {steps} steps: max error {err:.3g} of each "
        f"state's range {'<=' if err <= tol else '>'} {tol:g}",
    )
    return _raise_if_failed(f"{name}: exported C disagrees with Python", [c])
