"""Reference trajectories x_d(t) with the derivatives the controller needs.

Every reference returns ``(x_d, x_d', x_d'')`` at given times (length unit,
length unit/s, length unit/s^2) from :meth:`evaluate`, plus ``x_d'''`` from
:meth:`jerk` (used to derive the input-rate envelope).

- :class:`Sine`: ``offset + amplitude sin(2 pi f t + phase)``.
- :class:`Triangle`: same phase convention, ``offset + amplitude tri(2 pi f t +
  phase)`` with ``tri(theta) = (2/pi) arcsin(sin theta)``. At a sharp corner the
  velocity jumps, so ``x_d''`` is an impulse; a sampled controller cannot apply
  an impulse, and the paper's controller sees ``x_d'' = 0`` there. With
  ``corner_time = 0`` (the default, as in the paper) the corners are sharp and
  ``x_d''`` is 0 everywhere (the impulse is dropped). With ``corner_time = tau >
  0`` each corner is replaced by a parabolic blend of duration ``tau``
  (constant acceleration), so ``x_d''`` is finite and the feedforward is exact.
- :class:`Step`: ``offset`` before ``t_step``, ``offset + amplitude`` after it;
  with ``rise_time > 0`` a quintic (minimum-jerk) transition of that duration,
  so ``x_d'`` and ``x_d''`` are continuous: the smoothed reference that avoids
  observer peaking.

Every reference also states its structure, so that a certificate can cover it
at *every* time instead of a window: :attr:`~Reference.period` (periodic) or
:attr:`~Reference.settles_at` (constant from then on), the times where it is
not smooth (:meth:`~Reference.breakpoints`) and bounds on its derivatives
between them (:meth:`~Reference.derivative_bounds`). A reference class of one's
own that states neither a period nor a settling time, or does not implement the
two methods, can be simulated but not certified
(:func:`bwdesign.model.reference_cover.require_coverable`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..validate import SIGNAL, Range, real

__all__ = ["Reference", "Sine", "Triangle", "Step", "reference_from_dict"]


def _finite(value: Any, name: str, owner: str) -> float:
    """A reference field through :func:`bwdesign.validate.real` in its :data:`REFERENCE_RANGES`."""
    return real(value, f"{owner}: {name}", within=REFERENCE_RANGES[name], error=ConfigError)


#: Supported range of each reference field (length unit, Hz, rad, s).
REFERENCE_RANGES: dict[str, Range] = {
    "amplitude": SIGNAL,
    "offset": SIGNAL,
    "frequency": Range(0.0, 1e6, lo_open=True, unit="Hz"),
    "phase": Range(-1e6, 1e6, unit="rad"),
    "corner_time": Range(0.0, 1e6, unit="s"),
    "t_step": Range(-1e6, 1e6, unit="s"),
    "rise_time": Range(0.0, 1e6, unit="s"),
}


class Reference:
    """Base class: a trajectory with derivatives, sampled by :meth:`evaluate`."""

    kind: str = ""

    @property
    def period(self) -> float | None:
        """Period (s) for periodic references, ``None`` otherwise."""
        return None

    @property
    def settles_at(self) -> float | None:
        """Time (s) from which ``x_d`` is constant for ever (``x_d' = x_d'' = 0``).

        ``None`` for a reference that never settles (a periodic one).
        """
        return None

    def breakpoints(self, t0: float, t1: float) -> np.ndarray:
        """Times in ``[t0, t1]`` where ``x_d``, ``x_d'`` or ``x_d''`` may jump or kink.

        Between two consecutive breakpoints the reference is smooth and
        :meth:`derivative_bounds` holds. A subclass implements it to be certified.
        """
        raise NotImplementedError

    def derivative_bounds(self, t0: float, t1: float) -> tuple[float, float, float, float]:
        """Upper bounds on the 1st to 4th derivatives of ``x_d`` over the open ``(t0, t1)``.

        In that order; impulses at :meth:`breakpoints` are excluded (a jump is a
        breakpoint, not a rate). A subclass implements it to be certified.
        """
        raise NotImplementedError

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(x_d, x_d', x_d'')`` at times ``t`` (s)."""
        raise NotImplementedError

    def jerk(self, t: np.ndarray) -> np.ndarray:
        """Return ``x_d'''`` at times ``t`` (impulses are dropped)."""
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        raise NotImplementedError

    def describe(self) -> str:
        """One line for reports."""
        raise NotImplementedError


@dataclass(frozen=True, kw_only=True)
class Sine(Reference):
    """``offset + amplitude sin(2 pi frequency t + phase)``.

    Parameters
    ----------
    amplitude : float
        Half the peak-to-peak travel (length unit).
    offset : float
        Mean position (length unit).
    frequency : float
        Hz, > 0.
    phase : float
        rad.
    """

    amplitude: float
    offset: float = 0.0
    frequency: float
    phase: float = 0.0
    kind = "sine"

    def __post_init__(self) -> None:
        o = "sine reference"
        object.__setattr__(self, "amplitude", _finite(self.amplitude, "amplitude", o))
        object.__setattr__(self, "offset", _finite(self.offset, "offset", o))
        object.__setattr__(self, "frequency", _finite(self.frequency, "frequency", o))
        object.__setattr__(self, "phase", _finite(self.phase, "phase", o))

    @property
    def period(self) -> float:
        return 1.0 / self.frequency

    def evaluate(self, t):
        t = np.asarray(t, dtype=float)
        w = 2 * math.pi * self.frequency
        th = w * t + self.phase
        s, c = np.sin(th), np.cos(th)
        A = self.amplitude
        return self.offset + A * s, A * w * c, -A * w * w * s

    def jerk(self, t):
        w = 2 * math.pi * self.frequency
        return -self.amplitude * w**3 * np.cos(w * np.asarray(t, dtype=float) + self.phase)

    def breakpoints(self, t0, t1):
        return np.empty(0)

    def derivative_bounds(self, t0, t1):
        w, A = 2 * math.pi * self.frequency, abs(self.amplitude)
        return (A * w, A * w**2, A * w**3, A * w**4)

    def to_dict(self):
        return {
            "kind": "sine",
            "amplitude": self.amplitude,
            "offset": self.offset,
            "frequency": self.frequency,
            "phase": self.phase,
        }

    def describe(self):
        return (
            f"sine {self.amplitude:g} sin(2 pi {self.frequency:g} t"
            f"{self._phase_text()}) + {self.offset:g}"
        )

    def _phase_text(self) -> str:
        return "" if self.phase == 0 else f" {self.phase:+.4g}"


@dataclass(frozen=True, kw_only=True)
class Triangle(Reference):
    """Triangle wave with the sine's phase convention.

    ``offset + amplitude (2/pi) arcsin(sin(2 pi f t + phase))``; see the module
    docstring for the treatment of the corners (``corner_time``, s).
    """

    amplitude: float
    offset: float = 0.0
    frequency: float
    phase: float = 0.0
    corner_time: float = 0.0
    kind = "triangle"

    def __post_init__(self) -> None:
        o = "triangle reference"
        object.__setattr__(self, "amplitude", _finite(self.amplitude, "amplitude", o))
        object.__setattr__(self, "offset", _finite(self.offset, "offset", o))
        object.__setattr__(self, "frequency", _finite(self.frequency, "frequency", o))
        object.__setattr__(self, "phase", _finite(self.phase, "phase", o))
        object.__setattr__(self, "corner_time", _finite(self.corner_time, "corner_time", o))
        if self.corner_time >= 0.5 / self.frequency:
            raise ConfigError(
                f"triangle reference: corner_time must be shorter than half a period "
                f"({0.5 / self.frequency:g} s), got {self.corner_time:g}"
            )

    @property
    def period(self) -> float:
        return 1.0 / self.frequency

    def evaluate(self, t):
        t = np.asarray(t, dtype=float)
        T = 1.0 / self.frequency
        A = self.amplitude
        v = 4.0 * A * self.frequency  # slope magnitude
        # time since the last lower corner (theta = -pi/2 + 2 pi n)
        t0 = (-0.5 * math.pi - self.phase) / (2 * math.pi * self.frequency)
        tau = np.mod(t - t0, T)
        half = 0.5 * T
        rising = tau < half
        tl = np.where(rising, tau, tau - half)  # time since the last corner
        sgn = np.where(rising, 1.0, -1.0)  # slope sign on this leg
        base = -A + v * tl  # position along the leg, from its corner
        xd = sgn * base
        xdot = sgn * v
        xdd = np.zeros_like(t)
        c = self.corner_time
        if c > 0:
            acc = 2.0 * v / c  # reverses slope +-v in time c
            hc = 0.5 * c
            # entering the blend near the next corner: tl > half - hc
            late = tl > half - hc
            s_late = tl - (half - hc)
            # leaving the blend after the last corner: tl < hc
            early = tl < hc
            s_early = hc - tl
            # parabola: on the corner, position deficit 0.5 acc s^2 where s is the
            # distance to the blend edge; slope interpolates linearly.
            xd = np.where(late, sgn * (base - 0.5 * acc * s_late**2), xd)
            xdot = np.where(late, sgn * (v - acc * s_late), xdot)
            xdd = np.where(late, -sgn * acc, xdd)
            xd = np.where(early, sgn * (base + 0.5 * acc * s_early**2), xd)
            xdot = np.where(early, sgn * (v - acc * s_early), xdot)
            xdd = np.where(early, sgn * acc, xdd)
        return self.offset + xd, xdot, xdd

    def jerk(self, t):
        return np.zeros_like(np.asarray(t, dtype=float))

    def breakpoints(self, t0, t1):
        # corners every half period from a lower corner; blend edges half a blend either side
        half = 0.5 / self.frequency
        tc = (-0.5 * math.pi - self.phase) / (2 * math.pi * self.frequency)
        n0 = math.floor((t0 - tc) / half) - 1
        n1 = math.ceil((t1 - tc) / half) + 1
        corners = tc + half * np.arange(n0, n1 + 1)
        hc = 0.5 * self.corner_time
        pts = np.concatenate([corners - hc, corners, corners + hc]) if hc else corners
        return np.unique(pts[(pts >= t0) & (pts <= t1)])

    def derivative_bounds(self, t0, t1):
        v = 4.0 * abs(self.amplitude) * self.frequency
        acc = 2.0 * v / self.corner_time if self.corner_time > 0 else 0.0
        return (v, acc, 0.0, 0.0)

    def to_dict(self):
        return {
            "kind": "triangle",
            "amplitude": self.amplitude,
            "offset": self.offset,
            "frequency": self.frequency,
            "phase": self.phase,
            "corner_time": self.corner_time,
        }

    def describe(self):
        corners = (
            f", corners blended over {self.corner_time:g} s"
            if self.corner_time
            else ", sharp corners"
        )
        return (
            f"triangle {2 * self.amplitude:g} peak to peak at {self.frequency:g} Hz, "
            f"offset {self.offset:g}{corners}"
        )


@dataclass(frozen=True, kw_only=True)
class Step(Reference):
    """Step of ``amplitude`` at ``t_step`` from ``offset``; quintic rise over ``rise_time``."""

    amplitude: float
    offset: float = 0.0
    t_step: float = 0.0
    rise_time: float = 0.0
    kind = "step"

    def __post_init__(self) -> None:
        o = "step reference"
        object.__setattr__(self, "amplitude", _finite(self.amplitude, "amplitude", o))
        object.__setattr__(self, "offset", _finite(self.offset, "offset", o))
        object.__setattr__(self, "t_step", _finite(self.t_step, "t_step", o))
        object.__setattr__(self, "rise_time", _finite(self.rise_time, "rise_time", o))

    def evaluate(self, t):
        t = np.asarray(t, dtype=float)
        A, T = self.amplitude, self.rise_time
        if T == 0:
            return (
                self.offset + np.where(t >= self.t_step, A, 0.0),
                np.zeros_like(t),
                np.zeros_like(t),
            )
        s = np.clip((t - self.t_step) / T, 0.0, 1.0)
        inside = (t > self.t_step) & (t < self.t_step + T)
        pos = 10 * s**3 - 15 * s**4 + 6 * s**5
        vel = np.where(inside, (30 * s**2 - 60 * s**3 + 30 * s**4) / T, 0.0)
        acc = np.where(inside, (60 * s - 180 * s**2 + 120 * s**3) / T**2, 0.0)
        return self.offset + A * pos, A * vel, A * acc

    @property
    def settles_at(self) -> float:
        return self.t_step + self.rise_time

    def breakpoints(self, t0, t1):
        pts = np.array(sorted({self.t_step, self.t_step + self.rise_time}))
        return pts[(pts >= t0) & (pts <= t1)]

    def derivative_bounds(self, t0, t1):
        T, A = self.rise_time, abs(self.amplitude)
        if T == 0 or t1 <= self.t_step or t0 >= self.t_step + T:
            return (0.0, 0.0, 0.0, 0.0)
        # the quintic's derivatives on [0, 1] peak at 15/8, 10/sqrt(3), 60 and 360
        return (1.875 * A / T, 10 / math.sqrt(3) * A / T**2, 60.0 * A / T**3, 360.0 * A / T**4)

    def jerk(self, t):
        t = np.asarray(t, dtype=float)
        T = self.rise_time
        if T == 0:
            return np.zeros_like(t)
        s = np.clip((t - self.t_step) / T, 0.0, 1.0)
        inside = (t > self.t_step) & (t < self.t_step + T)
        return np.where(inside, self.amplitude * (60 - 360 * s + 360 * s**2) / T**3, 0.0)

    def to_dict(self):
        return {
            "kind": "step",
            "amplitude": self.amplitude,
            "offset": self.offset,
            "t_step": self.t_step,
            "rise_time": self.rise_time,
        }

    def describe(self):
        rise = f", quintic rise over {self.rise_time:g} s" if self.rise_time else ""
        return f"step of {self.amplitude:g} at t = {self.t_step:g} s from {self.offset:g}{rise}"


_KINDS: dict[str, type[Reference]] = {"sine": Sine, "triangle": Triangle, "step": Step}
_KEYS = {
    "sine": {"amplitude", "offset", "frequency", "phase"},
    "triangle": {"amplitude", "offset", "frequency", "phase", "corner_time"},
    "step": {"amplitude", "offset", "t_step", "rise_time"},
}


def reference_from_dict(data: dict[str, Any], *, owner: str = "[reference]") -> Reference:
    """Build a reference from a ``[reference]`` table (``kind`` plus its keys).

    Raises
    ------
    ConfigError
        Unknown kind, unknown or missing keys, non-numeric values.
    """
    if not isinstance(data, dict):
        raise ConfigError(f"{owner} must be a table")
    kind = data.get("kind")
    if not isinstance(kind, str) or kind not in _KINDS:
        raise ConfigError(f"{owner}: kind must be one of {', '.join(sorted(_KINDS))}, got {kind!r}")
    allowed = _KEYS[kind] | {"kind"}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ConfigError(
            f"{owner}: unknown key(s) {', '.join(unknown)} for kind {kind!r}; allowed keys "
            f"are {', '.join(sorted(allowed))}"
        )
    required = {"amplitude", "frequency"} if kind != "step" else {"amplitude"}
    missing = sorted(required - set(data))
    if missing:
        raise ConfigError(f"{owner}: missing key(s) {', '.join(missing)}")
    kwargs = {k: v for k, v in data.items() if k != "kind"}
    return _KINDS[kind](**kwargs)
