"""The checks behind ``bwdesign check``, the pytest helpers and the pytest plugin.

Each check computes a number from the stage and compares it with a limit, giving a
:class:`Check` (name, passed, value, limit, one-line text). The loop that the
tracking and margin checks use is the stage's own: eq. (12) with the
``[controller]`` constants, as printed, run at ``[sampling] dt`` on the PHSO (or
``observer``) with the ``[observer]`` gains; the tracking run starts on the
reference as the report's runs do (or from rest), follows ``[reference]`` and takes
its metrics over the last two reference periods.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..certify.synthesis import synthesize
from ..certify.tiers import certify
from ..control.analysis import analyze_loop
from ..control.loop import ON_REFERENCE, ClosedLoop, Start
from ..errors import ConfigError, InputError
from ..model.config import StageConfig, load_config
from ..model.params import MODEL_FIELDS, PRESETS, BoucWenParams, preset
from ..model.requirements import REQUIREMENT_KEYS
from ..observers.gains import hurwitz_violations
from ..sim.batch import simulate_batch

__all__ = [
    "Check",
    "as_stage",
    "check_certified",
    "check_synthesis",
    "check_tracking",
    "check_margins",
    "check_requirements",
    "failure_table",
]


@dataclass(frozen=True)
class Check:
    """One requirement, checked.

    Attributes
    ----------
    stage : str
        Name of the stage file (or plant).
    name : str
        Requirement key (``certified``, ``max_me_um``, ...).
    passed : bool
    value, limit : float or bool or None
        What was achieved and what was required.
    text : str
        One line: what was computed, with units.
    """

    stage: str
    name: str
    passed: bool
    value: Any
    limit: Any
    text: str
    details: dict[str, Any] = field(default_factory=dict, compare=False)

    def line(self) -> str:
        return f"{'PASS' if self.passed else 'FAIL'}  {self.stage}  {self.name}: {self.text}"


def as_stage(stage: Any) -> StageConfig:
    """A :class:`StageConfig` from a config path, a stage or plant preset name, or params."""
    if isinstance(stage, StageConfig):
        return stage
    if isinstance(stage, BoucWenParams):
        return StageConfig(plant=stage, source=stage.name or "params")
    if isinstance(stage, str | Path):
        try:
            return load_config(stage)
        except ConfigError:
            if isinstance(stage, str) and stage in PRESETS:
                return StageConfig(plant=preset(stage), source=stage)
            raise
    raise InputError(
        f"stage must be a config path, a preset name, a StageConfig or BoucWenParams, "
        f"got {type(stage).__name__}"
    )


def _name(config: StageConfig) -> str:
    return Path(config.source).name if config.source else (config.plant.name or "stage")


def _need(config: StageConfig, what: str, **items: Any) -> None:
    missing = [k for k, v in items.items() if v is None]
    if missing:
        raise ConfigError(f"{_name(config)}: {what} needs {', '.join(missing)}")


def _not_hurwitz(config: StageConfig, gains: Any) -> str | None:
    """Why the gains are not Hurwitz on the stage's plant (one line), or None when they are.

    Gains that are not stabilising are a failed requirement, not bad input: in a
    firmware repository that is the change the check exists to catch.
    """
    bad = hurwitz_violations(config.plant, gains)
    if not bad:
        return None
    text = ", ".join(f"{float(g):g}" for g in gains)
    return (
        f"observer gains l = ({text}) are not Hurwitz on {config.plant.name or 'the plant'} "
        f"(A = A0 - l C is unstable): they violate {'; '.join(bad)}"
    )


def _failed(config: StageConfig, name: str, limit: Any, why: str) -> Check:
    """A requirement that fails before anything is computed (value None)."""
    return Check(_name(config), name, False, None, limit, why)


def check_certified(
    config: StageConfig,
    *,
    gains: Any = None,
    udot_max: float | None = None,
    dt: float | None = None,
    tier: str | None = None,
    decay: float = 0.0,
) -> Check:
    """Are the gains certified at the envelope (by ``tier``, or by any tier)?"""
    gains = config.gains if gains is None else gains
    dt = config.dt if dt is None else dt
    if udot_max is None and config.envelope_spec is not None:
        udot_max = config.envelope().udot_max
    _need(
        config,
        "the certificate check",
        **{"[observer] gains": gains, "[envelope] (or udot_max)": udot_max},
    )
    why = _not_hurwitz(config, gains)
    if why is not None:
        c = _failed(config, "certified", tier or "any", f"no certificate: {why}")
        return replace(c, details={"report": None, "decay_rate": 0.0})
    rep = certify(config.plant, gains, udot_max=udot_max, dt=dt, decay=decay)
    holding = [c for c in rep.certificates if c.holds]
    if tier is not None:
        if tier not in [c.name for c in rep.certificates]:
            raise InputError(
                f"tier {tier!r} is not checked here; tiers: "
                f"{', '.join(c.name for c in rep.certificates)}"
            )
        holding = [c for c in holding if c.name == tier]
    ok = bool(holding)
    best = holding[-1] if holding else None
    want = f"the {tier} tier" if tier else "some tier"
    reach = (
        (
            "and at every rate searched"
            if not math.isfinite(best.max_udot)
            else f"up to {best.max_udot:.4g} V/s"
        )
        if best
        else ""
    )
    text = (
        f"{best.name} tier holds at |u'| <= {udot_max:.6g} V/s ({reach}), "
        f"decay {best.decay_rate:.4g} 1/s"
        if best
        else f"{want} needed at |u'| <= {udot_max:.6g} V/s, decay >= {decay:g} 1/s; none holds ("
        + ", ".join(f"{c.name} up to {c.max_udot:.4g} V/s" for c in rep.certificates)
        + ")"
    )
    return Check(
        _name(config),
        "certified",
        ok,
        best.name if best else None,
        tier or "any",
        text,
        details={"report": rep.to_dict(), "decay_rate": best.decay_rate if best else 0.0},
    )


def check_synthesis(
    config: StageConfig,
    *,
    udot_max: float,
    decay: float,
    dt: float | None = None,
    pole_radius: float | None = None,
) -> Check:
    """Does synthesis find certified gains for this envelope and decay?"""
    dt = config.dt if dt is None else dt
    syn = synthesize(config.plant, udot_max=udot_max, decay=decay, pole_radius=pole_radius, dt=dt)
    return Check(
        _name(config),
        "synthesis",
        syn.feasible,
        syn.feasible,
        True,
        syn.reason,
        details=syn.to_dict(),
    )


def _true_plants(config: StageConfig, mismatch: Mapping[str, float] | None) -> list[BoucWenParams]:
    p = config.plant
    if mismatch is not None:
        bad = sorted(set(mismatch) - set(MODEL_FIELDS))
        if bad:
            raise InputError(f"mismatch: unknown parameter(s) {bad}; parameters: {MODEL_FIELDS}")
        return [replace(p, **{k: getattr(p, k) * (1 + float(v)) for k, v in mismatch.items()})]
    box = getattr(config, "uncertainty", None)
    if box is not None:
        return [p, *box.vertices(p)]
    return [p]


def check_tracking(
    config: StageConfig,
    *,
    max_me: float | None = None,
    max_maxe: float | None = None,
    noise_std: float = 0.0,
    mismatch: Mapping[str, float] | None = None,
    observer: str = "phso",
    duration: float | None = None,
    start: str = "reference",
) -> list[Check]:
    """Simulated tracking of ``[reference]`` against ME / MAXE limits (um).

    ``start="reference"`` starts the loop on the reference as the report's runs do
    (``ClosedLoop(start="reference")``); ``"rest"`` from zero state and input.

    The worst case over the nominal plant and, without ``mismatch``, every corner
    of the ``[uncertainty]`` box (when the stage has one); with ``mismatch``
    (relative errors, e.g. ``{"a1": 0.02}``) the plant so perturbed.
    """
    _need(
        config,
        "the tracking check",
        **{
            "[observer] gains": config.gains,
            "[controller]": config.controller,
            "[sampling] dt": config.dt,
            "[reference]": config.reference,
        },
    )
    why = _not_hurwitz(config, config.gains)
    if why is not None:
        limits = (("max_me_um", max_me), ("max_maxe_um", max_maxe))
        return [_failed(config, k, v, f"not simulated: {why}") for k, v in limits if v is not None]
    period = config.reference.period
    duration = duration or max(1.0, 3 * period if period else 1.0)
    plants = _true_plants(config, mismatch)
    if start not in ("reference", "rest"):
        raise InputError(f"start must be 'reference' or 'rest', got {start!r}")
    loop = ClosedLoop.from_config(
        config, observer=observer, start=ON_REFERENCE if start == "reference" else Start()
    )
    res = simulate_batch(
        loop, config.reference, plants, duration=duration, noise_std=noise_std, seeds=1
    )
    if mismatch is not None:
        where = "plant " + ", ".join(f"{k} {100 * float(v):+g} %" for k, v in mismatch.items())
    else:
        where = "nominal" if len(plants) == 1 else f"worst of nominal and {len(plants) - 1} corners"
    lu = config.plant.length_unit
    out = []
    for name, limit, values in (("max_me_um", max_me, res.me), ("max_maxe_um", max_maxe, res.maxe)):
        if limit is None:
            continue
        if not res.stable.all():
            i = int(res.stable.argmin())
            out.append(
                Check(
                    _name(config),
                    name,
                    False,
                    math.inf,
                    limit,
                    f"the loop is unstable on plant {i} ({res.status[i]})",
                )
            )
            continue
        worst = float(values.max())
        label = "ME" if name == "max_me_um" else "MAXE"
        out.append(
            Check(
                _name(config),
                name,
                worst <= limit,
                worst,
                limit,
                f"{label} {worst:.4g} {lu} ({where}, {observer.upper()}, noise {noise_std:g} {lu}, "
                f"from {start}) "
                f"{'<=' if worst <= limit else '>'} {limit:g}",
            )
        )
    return out


def check_margins(
    config: StageConfig,
    *,
    min_gain_margin_db: float | None = None,
    min_phase_margin_deg: float | None = None,
) -> list[Check]:
    """Gain and phase margins of the sampled loop (observer + eq. 12 at dt)."""
    _need(
        config,
        "the margin check",
        **{
            "[observer] gains": config.gains,
            "[controller]": config.controller,
            "[sampling] dt": config.dt,
        },
    )
    why = _not_hurwitz(config, config.gains)
    if why is not None:
        limits = (
            ("min_gain_margin_db", min_gain_margin_db),
            ("min_phase_margin_deg", min_phase_margin_deg),
        )
        return [_failed(config, k, v, f"not analysed: {why}") for k, v in limits if v is not None]
    ctl = config.controller
    loop = analyze_loop(config.plant, ctl.lambda1, ctl.lambda2, config.gains, dt=config.dt)
    out = []
    if min_gain_margin_db is not None:
        v = float(loop.gain_margin_db)
        out.append(
            Check(
                _name(config),
                "min_gain_margin_db",
                v >= min_gain_margin_db,
                v,
                min_gain_margin_db,
                f"gain margin {v:.3g} dB {'>=' if v >= min_gain_margin_db else '<'} "
                f"{min_gain_margin_db:g} dB (stable: {loop.stable})",
            )
        )
    if min_phase_margin_deg is not None:
        v = float(loop.phase_margin)
        out.append(
            Check(
                _name(config),
                "min_phase_margin_deg",
                v >= min_phase_margin_deg,
                v,
                min_phase_margin_deg,
                f"phase margin {v:.3g} deg {'>=' if v >= min_phase_margin_deg else '<'} "
                f"{min_phase_margin_deg:g} deg",
            )
        )
    return out


def check_requirements(stage: Any) -> list[Check]:
    """Every requirement of the stage's ``[requirements]`` section, in the schema's order."""
    config = as_stage(stage)
    req = config.requirements
    if not req:
        raise ConfigError(f"{_name(config)}: no [requirements] section to check")
    out: list[Check] = []
    if req.get("certified") or "min_decay" in req:
        c = check_certified(config)
        if req.get("certified"):
            out.append(c)
        if "min_decay" in req:
            v = float(c.details["decay_rate"])
            lim = req["min_decay"]
            text = f"certified decay {v:.4g} 1/s {'>=' if v >= lim else '<'} {lim:g}"
            if c.details["report"] is None:  # nothing was certified: say why
                text = c.text
            out.append(Check(c.stage, "min_decay", v >= lim, v, lim, text))
    if "max_me_um" in req or "max_maxe_um" in req:
        out += check_tracking(
            config,
            max_me=req.get("max_me_um"),
            max_maxe=req.get("max_maxe_um"),
            noise_std=req.get("noise_std_um", 0.0),
            observer=req.get("observer", "phso"),
            duration=req.get("duration_s"),
            start=req.get("start", "reference"),
        )
    if "min_gain_margin_db" in req or "min_phase_margin_deg" in req:
        out += check_margins(
            config,
            min_gain_margin_db=req.get("min_gain_margin_db"),
            min_phase_margin_deg=req.get("min_phase_margin_deg"),
        )
    order = list(REQUIREMENT_KEYS)
    return sorted(out, key=lambda c: order.index(c.name))


def failure_table(checks: list[Check]) -> str:
    """A short, aligned table of checks (for AssertionError messages)."""
    rows = [("", "requirement", "required", "achieved", "")] + [
        ("PASS" if c.passed else "FAIL", c.name, _fmt(c.limit), _fmt(c.value), c.text)
        for c in checks
    ]
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    return "\n".join(
        "  ".join(r[i].ljust(widths[i]) for i in range(4)) + "  " + r[4] for r in rows
    ).rstrip()


def _fmt(v: Any) -> str:
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return str(v)
    return f"{v:.4g}"
