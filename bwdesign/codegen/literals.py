"""C literals that carry a Python float exactly, in the precision of the generated code."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError

__all__ = ["PRECISIONS", "CTypes", "c_literal"]

#: The generated code's arithmetic, by its ``--precision`` name.
PRECISIONS = ("float32", "float64")


class CTypes:
    """Names the templates substitute for one precision (type, math functions, constants)."""

    def __init__(self, precision: str) -> None:
        if precision not in PRECISIONS:
            raise InputError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
        self.precision = precision
        single = precision == "float32"
        self.real = "float" if single else "double"
        suffix = "f" if single else ""
        self.fabs = "fabs" + suffix
        self.expm1, self.log1p = "expm1" + suffix, "log1p" + suffix

    def literal(self, value: float) -> str:
        return c_literal(value, self.precision)

    def names(self) -> dict[str, str]:
        """Template keys shared by every file: type, functions and small constants."""
        lit = self.literal
        return {
            "real": self.real,
            "fabs": self.fabs,
            "expm1": self.expm1,
            "log1p": self.log1p,
            "zero": lit(0.0),
            "one": lit(1.0),
            "two": lit(2.0),
            "six": lit(6.0),
            "half": lit(0.5),
            "tiny": lit(1e-8),
            "crossing_floor": lit(1e-6),
        }


def c_literal(value: float, precision: str) -> str:
    """``value`` as a C99 hexadecimal floating constant, exact in ``precision``.

    float64 literals are the double exactly (``float.hex``); float32 literals are
    the value rounded to the nearest float32, written exactly with the ``f``
    suffix so that nothing is promoted to double.

    Raises
    ------
    InputError
        ``value`` is not finite, or overflows float32.
    """
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"cannot write the non-finite constant {value!r} as C")
    if precision == "float64":
        return value.hex()
    with np.errstate(over="ignore"):
        single = float(np.float32(value))
    if not math.isfinite(single):
        raise InputError(f"the constant {value!r} overflows float32; export with float64")
    return single.hex() + "f"
