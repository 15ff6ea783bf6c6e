"""The plant summary document: parameters, derived linear quantities, bounded-class verdict."""

from __future__ import annotations

import math
from typing import Any

from .params import PRESET_NOTES, BoucWenParams


def plant_summary(params: BoucWenParams) -> dict[str, Any]:
    """Parameters, derived linear quantities and the bounded-class verdict."""
    verdict = params.bounded_class()
    wn = math.sqrt(params.a1)
    doc: dict[str, Any] = {
        "plant": params.to_dict(),
        "derived": {
            "natural_frequency_hz": wn / (2 * math.pi),
            "damping_ratio": params.a2 / (2 * wn),
            "static_gain": params.static_gain,
            "static_gain_unit": f"{params.length_unit}/{params.input_unit}",
        },
        "bounded_class": verdict.to_dict(),
    }
    if params.name in PRESET_NOTES:
        doc["note"] = PRESET_NOTES[params.name]
    return doc
