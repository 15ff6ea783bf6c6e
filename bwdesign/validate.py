"""Numbers checked one way everywhere: on the command line, in TOML and in Python.

A number is accepted when it is a :class:`numbers.Real` (Python ``int`` and
``float``, numpy scalars such as ``np.float64`` or ``np.int32``) but not a
``bool``, is finite and lies in the stated supported :class:`Range`; an integer
must be a :class:`numbers.Integral` (``3.0`` is refused where an integer is
meant). Strings are refused in Python and TOML; on the command line
:func:`parse_real` and :func:`parse_integer` turn the text into a number first
and then apply the very same checks.

Every failure raises the error class the caller names (a subclass of
:class:`~bwdesign.errors.BWDesignError`: ``InputError`` by default,
``ParameterError`` for model parameters, ``ConfigError`` for files), with a
message that names the quantity, the supported range and what was found.

The supported ranges of the package's public inputs are the constants below
(``DT``, ``UDOT_MAX``, ...). They are wide enough for every real stage and
narrow enough that no arithmetic inside bwdesign overflows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any

from .errors import BWDesignError, InputError, ParameterError

__all__ = [
    "input_limits",
    "Range",
    "real",
    "integer",
    "parse_real",
    "parse_integer",
    "below_nyquist",
    "DT",
    "UDOT_MAX",
    "UDOT_BOUND",
    "DECAY",
    "POLE_RADIUS",
    "LAMBDA",
    "GAIN",
    "SEED",
    "SIGNAL",
    "POSITIVE",
    "NONNEGATIVE",
]


@dataclass(frozen=True)
class Range:
    """A closed or half-open interval of supported values.

    Parameters
    ----------
    lo, hi : float
        Bounds (``-inf``/``inf`` for none).
    lo_open, hi_open : bool
        Exclude the bound itself.
    unit : str
        Unit printed after the interval in messages.
    """

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False
    unit: str = ""

    def __contains__(self, x: float) -> bool:
        above = x > self.lo if self.lo_open else x >= self.lo
        below = x < self.hi if self.hi_open else x <= self.hi
        return above and below

    def text(self) -> str:
        """The interval as ``[1e-09, 1] s`` (for messages)."""
        left = "(" if self.lo_open or math.isinf(self.lo) else "["
        right = ")" if self.hi_open or math.isinf(self.hi) else "]"
        body = f"{left}{self.lo:g}, {self.hi:g}{right}"
        return f"{body} {self.unit}".rstrip()


def _fail(error: type[BWDesignError], message: str, name: str) -> BWDesignError:
    if issubclass(error, ParameterError):
        return error(message, field=name.rpartition(": ")[2])
    return error(message)


def real(
    value: Any,
    name: str,
    *,
    within: Range | None = None,
    error: type[BWDesignError] = InputError,
) -> float:
    """``value`` as a finite float inside ``within``, or raise ``error``.

    Parameters
    ----------
    value : numbers.Real
        ``bool`` and ``str`` are refused.
    name : str
        What the number is, for messages (e.g. ``"dt (s)"``, ``"[sampling] dt"``);
        for a ``ParameterError`` its last ``": "``-separated part is the ``field``.
    within : Range, optional
        Supported interval; None accepts any finite number.
    error : type
        Error class raised (``InputError``, ``ParameterError``, ``ConfigError``).

    Returns
    -------
    float

    Examples
    --------
    >>> import numpy as np
    >>> real(np.float32(0.5), "dt", within=DT)
    0.5
    """
    if isinstance(value, bool) or not isinstance(value, Real):
        raise _fail(error, f"{name} must be a number, got {type(value).__name__} {value!r}", name)
    try:
        x = float(value)
    except (OverflowError, ValueError):
        x = math.inf
    if not math.isfinite(x):
        raise _fail(error, f"{name} must be finite, got {value!r}", name)
    if within is not None and x not in within:
        raise _fail(error, f"{name} = {x:g} is outside the supported range {within.text()}", name)
    return x


def integer(
    value: Any,
    name: str,
    *,
    within: Range | None = None,
    error: type[BWDesignError] = InputError,
) -> int:
    """``value`` as an int inside ``within``, or raise ``error``.

    ``numbers.Integral`` only (numpy integers included); ``bool``, floats
    (even ``3.0``) and strings are refused.
    """
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise _fail(error, f"{name} must be an integer, got {type(value).__name__} {value!r}", name)
    n = int(value)
    if within is not None and n not in within:
        raise _fail(error, f"{name} = {n} is outside the supported range {within.text()}", name)
    return n


def parse_real(
    text: str,
    name: str,
    *,
    within: Range | None = None,
    error: type[BWDesignError] = InputError,
) -> float:
    """Command-line text to a number, then the checks of :func:`real`."""
    try:
        value = float(text)
    except ValueError:
        raise _fail(error, f"{name} must be a number, got {text!r}", name) from None
    return real(value, name, within=within, error=error)


def parse_integer(
    text: str,
    name: str,
    *,
    within: Range | None = None,
    error: type[BWDesignError] = InputError,
) -> int:
    """Command-line text to an integer, then the checks of :func:`integer`."""
    try:
        value = int(text.strip())
    except ValueError:
        raise _fail(error, f"{name} must be an integer, got {text!r}", name) from None
    return integer(value, name, within=within, error=error)


def below_nyquist(
    reference: Any,
    dt: float,
    *,
    what: str = "the reference",
    error: type[BWDesignError] = InputError,
) -> None:
    """Refuse a periodic reference at or above the Nyquist frequency ``1/(2 dt)``.

    A loop sampled every ``dt`` cannot follow a reference whose fundamental
    ``1/period`` reaches ``1/(2 dt)``: the samples alias it to a lower frequency
    (at exactly ``1/(2 dt)`` a sine may be sampled at its zero crossings), and a
    simulation of it only "diverges". Checked wherever a reference meets a sample
    time. A reference without a period (a step) passes.

    Parameters
    ----------
    reference : Reference
        Anything with a ``period`` (s) or ``None``.
    dt : float
        Sample time (s), already checked.
    what : str
        Name of the reference in the message.
    error : type
        Error class raised.
    """
    period = getattr(reference, "period", None)
    if not period:
        return
    f, nyquist = 1.0 / float(period), 1.0 / (2.0 * float(dt))
    if f >= nyquist:
        raise error(
            f"{what} frequency {f:g} Hz is at or above the Nyquist frequency 1/(2 dt) = "
            f"{nyquist:g} Hz of dt = {float(dt):g} s: the sampled loop cannot follow it "
            "(lower the frequency or shorten dt)"
        )


#: Sample time (s). The plant adds its own bound (see ``bwdesign.model.plant``).
DT = Range(1e-9, 1.0, unit="s")
#: Input-rate envelope |u'| (V/s).
UDOT_MAX = Range(0.0, 1e9, lo_open=True, unit="V/s")
#: An input-rate bound where 0 is meaningful (an analysis with the input at rest) (V/s).
UDOT_BOUND = Range(0.0, 1e9, unit="V/s")
#: Required decay rate of the estimation error (1/s).
DECAY = Range(0.0, 1e9, unit="1/s")
#: The eq. (12) constants lambda1, lambda2 and the integral rate of the controller (1/s).
LAMBDA = Range(0.0, 1e12, lo_open=True, unit="1/s")
#: Pole radius of the gain synthesis (rad/s).
POLE_RADIUS = Range(0.0, 1e12, lo_open=True, unit="rad/s")
#: Each continuous observer gain l1, l2, l3 (1/s, 1/s^2, 1/s).
GAIN = Range(-1e15, 1e15)
#: Random seeds: non-negative integers (numpy's SeedSequence range).
SEED = Range(0, math.inf)
#: Signal levels: reference amplitude and offset, input limits (plant units, V).
SIGNAL = Range(-1e9, 1e9)
#: Any finite number > 0, for quantities with no narrower supported range.
POSITIVE = Range(0.0, math.inf, lo_open=True)
#: Any finite number >= 0 (counts, noise levels), for quantities with no narrower range.
NONNEGATIVE = Range(0.0, math.inf)


def input_limits(u_limits: Any) -> tuple[float, float] | None:
    """``(u_min, u_max)`` of a controller's input limits (V), or ``None`` for none.

    Raises
    ------
    InputError
        Not a pair of numbers, a NaN, or ``u_min >= u_max``.
    """
    if u_limits is None:
        return None
    try:
        lo, hi = (float(v) for v in u_limits)
    except (TypeError, ValueError):
        raise InputError(f"u_limits must be a pair (u_min, u_max) in V, got {u_limits!r}") from None
    if math.isnan(lo) or math.isnan(hi) or not lo < hi:
        raise InputError(f"u_limits must satisfy u_min < u_max, got ({lo}, {hi})")
    return (lo, hi)
