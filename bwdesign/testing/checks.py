"""The checks behind ``bwdesign check``, the pytest helpers and the pytest plugin.

Each check reads a number from the stage's computed study (:func:`bwdesign.study.study`,
the parts its requirements name) and compares it with a limit, giving a
:class:`Check` (name, passed, value, limit, one-line text):

- ``certified``, ``min_decay``: the study's ``configured`` certificate (the report's);
- ``max_me_um``, ``max_maxe_um``: its ``corner_tracking``, eq. (12) with the
  ``[controller]`` constants at ``[sampling] dt`` on the PHSO (or ``observer``) with
  the ``[observer]`` gains, on the nominal plant and every ``[uncertainty]`` corner,
  starting on the reference as the report's runs do (or from rest), metrics over the
  last two reference periods;
- ``min_gain_margin_db``, ``min_phase_margin_deg``: its ``loop`` analysis at dt (the
  report's "eq. 12, sampled at dt" row);
- synthesis: its ``synthesis``;
- ``baseline_stable``: its ``baseline`` part, the ``[baseline]`` PI/PID's sampled
  nominal linear loop (stable at the tuning slope and over the hysteresis slope range).

:func:`check_requirements` computes one study for all of a file's requirements.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..errors import ConfigError, InputError
from ..model.config import StageConfig, load_config
from ..model.params import PRESETS, BoucWenParams, preset
from ..model.requirements import REQUIREMENT_KEYS
from ..observers.gains import hurwitz_violations
from ..study import Study, StudySettings, study
from ..study.cache import StudyCache

__all__ = [
    "Check",
    "as_stage",
    "check_certified",
    "check_synthesis",
    "check_tracking",
    "check_margins",
    "check_baseline",
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


def _certified(config: StageConfig, s: Study, tier: str | None, decay: float) -> Check:
    """The ``certified`` check from the study's ``configured`` certificate."""
    rep, udot_max = s.configured, s.envelope.udot_max
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


def _not_certified(config: StageConfig, tier: str | None, why: str) -> Check:
    c = _failed(config, "certified", tier or "any", f"no certificate: {why}")
    return replace(c, details={"report": None, "decay_rate": 0.0})


def _need_certificate(config: StageConfig, gains: Any, udot_max: float | None) -> None:
    _need(
        config,
        "the certificate check",
        **{"[observer] gains": gains, "[envelope] (or udot_max)": udot_max},
    )


def _stage_envelope(config: StageConfig) -> float | None:
    return None if config.envelope_spec is None else config.envelope().udot_max


def check_certified(
    config: StageConfig,
    *,
    gains: Any = None,
    udot_max: float | None = None,
    dt: float | None = None,
    tier: str | None = None,
    decay: float = 0.0,
) -> Check:
    """Are the gains certified at the envelope (by ``tier``, or by any tier)?

    ``gains``, ``udot_max`` and ``dt`` default to the stage's; given, they replace its
    ``[observer]``, ``[envelope]`` and ``[sampling]`` in the study.
    """
    if udot_max is None:
        udot_max = _stage_envelope(config)
        envelope = config.envelope_spec
    else:
        envelope = {"udot_max": udot_max}
    gains = config.gains if gains is None else gains
    _need_certificate(config, gains, udot_max)
    why = _not_hurwitz(config, gains)
    if why is not None:
        return _not_certified(config, tier, why)
    asked = replace(
        config,
        gains=tuple(gains),
        dt=config.dt if dt is None else dt,
        envelope_spec=envelope,
    )
    s = study(asked, parts={"configured"}, settings=StudySettings(decay=decay))
    return _certified(config, s, tier, decay)


def check_synthesis(
    config: StageConfig,
    *,
    udot_max: float,
    decay: float,
    dt: float | None = None,
    pole_radius: float | None = None,
) -> Check:
    """Does synthesis find certified gains for this envelope and decay?

    The study's ``synthesis`` of the stage with ``[envelope] udot_max`` and
    ``[synthesis] decay, pole_radius`` as given (``dt`` default the stage's).
    """
    asked = replace(
        config,
        dt=config.dt if dt is None else dt,
        envelope_spec={"udot_max": udot_max},
        synthesis={"decay": decay, "pole_radius": pole_radius},
    )
    syn = study(asked, parts={"synthesis"}).synthesis.result
    return Check(
        _name(config),
        "synthesis",
        syn.feasible,
        syn.feasible,
        True,
        syn.reason,
        details=syn.to_dict(),
    )


def _need_tracking(config: StageConfig) -> None:
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


_TRACKING = (("max_me_um", "me", "ME"), ("max_maxe_um", "maxe", "MAXE"))


def _tracking(config: StageConfig, s: Study, limits: Mapping[str, float | None]) -> list[Check]:
    """The tracking checks from the study's ``corner_tracking``."""
    part = s.corner_tracking
    st, res = part.settings, part.result
    if st.mismatch is not None:
        where = "plant " + ", ".join(f"{k} {100 * float(v):+g} %" for k, v in st.mismatch.items())
    else:
        where = "nominal" if part.plants == 1 else f"worst of nominal and {part.plants - 1} corners"
    lu = config.plant.length_unit
    out = []
    for name, column, label in _TRACKING:
        limit = limits.get(name)
        if limit is None:
            continue
        if not res.stable.all():
            i = int(res.stable.argmin())
            why = f"the loop is unstable on plant {i} ({res.status[i]})"
            out.append(Check(_name(config), name, False, math.inf, limit, why))
            continue
        worst = float(getattr(res, column).max())
        out.append(
            Check(
                _name(config),
                name,
                worst <= limit,
                worst,
                limit,
                f"{label} {worst:.4g} {lu} ({where}, {st.observer.upper()}, noise "
                f"{st.noise_std:g} {lu}, from {st.start}) "
                f"{'<=' if worst <= limit else '>'} {limit:g}",
            )
        )
    return out


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
    (relative errors, e.g. ``{"a1": 0.02}``) the plant so perturbed. The study's
    ``corner_tracking`` part.
    """
    _need_tracking(config)
    limits = {"max_me_um": max_me, "max_maxe_um": max_maxe}
    why = _not_hurwitz(config, config.gains)
    if why is not None:
        return _not_simulated(config, limits, why)
    settings = StudySettings(
        observer=observer,
        noise_std=noise_std,
        duration=duration,
        start=start,
        mismatch=mismatch,
    )
    s = study(config, parts={"corner_tracking"}, settings=settings)
    return _tracking(config, s, limits)


def _not_simulated(
    config: StageConfig, limits: Mapping[str, float | None], why: str
) -> list[Check]:
    return [
        _failed(config, k, v, f"not simulated: {why}") for k, v in limits.items() if v is not None
    ]


def _need_margins(config: StageConfig) -> None:
    _need(
        config,
        "the margin check",
        **{
            "[observer] gains": config.gains,
            "[controller]": config.controller,
            "[sampling] dt": config.dt,
        },
    )


def _margins(config: StageConfig, s: Study, gm: float | None, pm: float | None) -> list[Check]:
    """The margin checks from the study's ``loop`` analysis at dt."""
    loop = s.loop.sampled
    out = []
    if gm is not None:
        v = float(loop.gain_margin_db)
        out.append(
            Check(
                _name(config),
                "min_gain_margin_db",
                v >= gm,
                v,
                gm,
                f"gain margin {v:.3g} dB {'>=' if v >= gm else '<'} {gm:g} dB "
                f"(stable: {loop.stable})",
            )
        )
    if pm is not None:
        v = float(loop.phase_margin)
        out.append(
            Check(
                _name(config),
                "min_phase_margin_deg",
                v >= pm,
                v,
                pm,
                f"phase margin {v:.3g} deg {'>=' if v >= pm else '<'} {pm:g} deg",
            )
        )
    return out


def _not_analysed(config: StageConfig, gm: float | None, pm: float | None, why: str) -> list:
    limits = (("min_gain_margin_db", gm), ("min_phase_margin_deg", pm))
    return [_failed(config, k, v, f"not analysed: {why}") for k, v in limits if v is not None]


def check_margins(
    config: StageConfig,
    *,
    min_gain_margin_db: float | None = None,
    min_phase_margin_deg: float | None = None,
) -> list[Check]:
    """Gain and phase margins of the sampled loop (observer + eq. 12 at dt)."""
    _need_margins(config)
    gm, pm = min_gain_margin_db, min_phase_margin_deg
    why = _not_hurwitz(config, config.gains)
    if why is not None:
        return _not_analysed(config, gm, pm, why)
    return _margins(config, study(config, parts={"loop"}), gm, pm)


def _baseline_stable(config: StageConfig, s: Study) -> Check:
    """The ``baseline_stable`` check from the study's ``baseline`` analysis."""
    b = s.baseline
    a = b.analysis
    return Check(
        _name(config),
        "baseline_stable",
        a.stable,
        a.stable,
        True,
        f"[baseline] {b.kind}: {a.describe()}",
        details={"baseline": b.to_dict()},
    )


def check_baseline(config: StageConfig, *, cache: StudyCache | None = None) -> Check:
    """Is the ``[baseline]`` controller's sampled nominal loop stable (with its margins)?"""
    _need(
        config, "the baseline check", **{"[baseline]": config.baseline, "[sampling] dt": config.dt}
    )
    return _baseline_stable(config, study(config, parts={"baseline"}, cache=cache))


def _min_decay(c: Check, limit: float) -> Check:
    v = float(c.details["decay_rate"])
    text = f"certified decay {v:.4g} 1/s {'>=' if v >= limit else '<'} {limit:g}"
    if c.details["report"] is None:  # nothing was certified: say why
        text = c.text
    return Check(c.stage, "min_decay", v >= limit, v, limit, text)


def check_requirements(stage: Any, *, cache: StudyCache | None = None) -> list[Check]:
    """Every requirement of the stage's ``[requirements]`` section, in the schema's order.

    One study of the stage, with the parts the requirements read, behind every check
    (read from and kept in ``cache`` when given: :mod:`bwdesign.study.cache`).
    """
    config = as_stage(stage)
    req = config.requirements
    if not req:
        raise ConfigError(f"{_name(config)}: no [requirements] section to check")
    certified = bool(req.get("certified")) or "min_decay" in req
    tracking = {k: req[k] for k, _, _ in _TRACKING if k in req}
    gm, pm = req.get("min_gain_margin_db"), req.get("min_phase_margin_deg")
    parts = set()
    if certified:
        _need_certificate(config, config.gains, _stage_envelope(config))
        parts.add("configured")
    if tracking:
        _need_tracking(config)
        parts.add("corner_tracking")
    if gm is not None or pm is not None:
        _need_margins(config)
        parts.add("loop")
    why = _not_hurwitz(config, config.gains) if parts else None
    s = None if why is not None or not parts else study(config, parts=parts, cache=cache)
    out: list[Check] = []
    if certified:
        c = _not_certified(config, None, why) if s is None else _certified(config, s, None, 0.0)
        out += [c] if req.get("certified") else []
        out += [_min_decay(c, req["min_decay"])] if "min_decay" in req else []
    if tracking:
        out += (
            _not_simulated(config, tracking, why) if s is None else _tracking(config, s, tracking)
        )
    if gm is not None or pm is not None:
        out += _not_analysed(config, gm, pm, why) if s is None else _margins(config, s, gm, pm)
    if req.get("baseline_stable"):
        out.append(check_baseline(config, cache=cache))
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
