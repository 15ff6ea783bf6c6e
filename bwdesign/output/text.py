"""Numbers as the reports and verdicts print them (one formatting for every text bwdesign writes).

Lives in the output layer so that both the computed study (its verdict sentence) and
the report's renderer format a number the same way.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["fmt", "gains_text", "limits_text"]


def fmt(x: Any, digits: int = 4) -> str:
    """A table cell: ``digits`` significant digits, "-" for None/NaN, "unbounded" for +inf."""
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float | int | np.floating):
        x = float(x)
        if math.isinf(x):
            return "unbounded" if x > 0 else "-inf"
        if math.isnan(x):
            return "-"
        return f"{x:.{digits}g}"
    return str(x)


def gains_text(gains: Any) -> str:
    """Gains as ``(g1, g2, g3)`` with 6 significant digits; "-" for None."""
    if gains is None:
        return "-"
    return "(" + ", ".join(f"{float(v):.6g}" for v in gains) + ")"


def limits_text(limits: Any, iu: str) -> str:
    """Input limits ``(lo, hi)`` as ``lo .. hi unit`` ("none" without limits)."""
    if limits is None:
        return "none"
    return f"{fmt(limits[0])} .. {fmt(limits[1])} {iu}"
