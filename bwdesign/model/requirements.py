"""The ``[requirements]`` section of a stage file: what a user's CI demands of the stage.

::

    [requirements]
    certified = true             # the configured gains hold (some tier) at the envelope
    min_decay = 20.0             # 1/s: the certified decay rate of the estimation error
    max_me_um = 45.0             # simulated reference tracking: mean |e| over the metrics window
    max_maxe_um = 80.0           #   and max |e|, worst over the [uncertainty] corners when present
    min_gain_margin_db = 6.0     # the sampled tracking loop (observer + eq. 12 at dt)
    min_phase_margin_deg = 30.0
    baseline_stable = true       # the [baseline] PI/PID's nominal loop (needs [baseline])
    # how the tracking is simulated (optional)
    observer = "phso"            # "phso" | "eso"
    noise_std_um = 0.0           # sensor noise std, seeded
    duration_s = 3.0             # default: three reference periods, at least 1 s
    start = "reference"          # as the report's runs; or "rest" (zero state and input)

Checked by ``bwdesign check`` and :mod:`bwdesign.testing`. Every key is
optional; unknown keys and wrong types are :class:`~bwdesign.errors.ConfigError`.
"""

from __future__ import annotations

from typing import Any

from ..errors import ConfigError
from ..validate import NONNEGATIVE, POSITIVE, Range, real

__all__ = ["REQUIREMENT_KEYS", "SETTING_KEYS", "parse_requirements"]

#: Requirement keys: (type, meaning with unit). Order is the order of ``bwdesign check``.
REQUIREMENT_KEYS: dict[str, tuple[type, str]] = {
    "certified": (bool, "the configured gains are certified at the envelope"),
    "min_decay": (float, "certified decay rate of the estimation error >= value (1/s)"),
    "max_me_um": (float, "simulated tracking ME <= value (um)"),
    "max_maxe_um": (float, "simulated tracking MAXE <= value (um)"),
    "min_gain_margin_db": (float, "gain margin of the sampled loop >= value (dB)"),
    "min_phase_margin_deg": (float, "phase margin of the sampled loop >= value (deg)"),
    "baseline_stable": (bool, "the [baseline] controller's sampled nominal loop is stable"),
}
#: Settings of the tracking simulation the requirements use.
SETTING_KEYS: dict[str, tuple[type, str]] = {
    "observer": (str, '"phso" or "eso"'),
    "noise_std_um": (float, "sensor noise std (um), >= 0"),
    "duration_s": (float, "simulated time (s), > 0"),
    "start": (str, '"reference" (as the report: on the reference at t = 0) or "rest"'),
}

#: Supported range of each number that is not :data:`~bwdesign.validate.NONNEGATIVE`.
_RANGES = {"min_gain_margin_db": Range(), "duration_s": POSITIVE}


def parse_requirements(table: Any) -> dict[str, Any]:
    """Validate a ``[requirements]`` table; returns it with numbers as floats."""
    if not isinstance(table, dict):
        raise ConfigError("[requirements] must be a table")
    allowed = {**REQUIREMENT_KEYS, **SETTING_KEYS}
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ConfigError(
            f"[requirements]: unknown key(s) {', '.join(unknown)}; allowed keys are "
            f"{', '.join(allowed)}"
        )
    out: dict[str, Any] = {}
    for key, value in table.items():
        kind, _ = allowed[key]
        if kind is bool:
            if not isinstance(value, bool):
                raise ConfigError(f"[requirements] {key} must be true or false, got {value!r}")
            out[key] = value
        elif kind is float:
            out[key] = real(
                value,
                f"[requirements] {key}",
                within=_RANGES.get(key, NONNEGATIVE),
                error=ConfigError,
            )
        else:
            choices = ("phso", "eso") if key == "observer" else ("reference", "rest")
            if value not in choices:
                raise ConfigError(
                    f"[requirements] {key} must be one of {', '.join(map(repr, choices))}, "
                    f"got {value!r}"
                )
            out[key] = value
    return out
