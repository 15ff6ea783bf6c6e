"""Which observer a loop runs: the observer specification, one type for the whole package.

An :class:`ObserverSpec` names the observer kind and carries its continuous gains in
the kind's own shape: three for the PHSO and the ESO, four ``(l1, l2, l3, l4)`` for the
disturbance observer (PHDO), none for the UKF (whose noise model needs the input-rate
envelope instead). :meth:`ObserverSpec.of` is the one place where a 3-state design
meets the PHDO: it runs ``(l1, l2, 0, l3)``
(:func:`~bwdesign.observers.gains.gains_for_observer`). A user's own observer (an
object with ``predict(u)``, ``update(z)`` and ``x``, or a factory
``factory(params, dt)``) is :meth:`ObserverSpec.custom`.

Whether the gains suit a model (the Hurwitz conditions) is checked where a spec meets
one: :class:`bwdesign.control.loop.ClosedLoop`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..errors import GainError, InputError
from ..validate import GAIN, UDOT_MAX, real
from .gains import GAIN_OBSERVERS, gains_for_observer

__all__ = [
    "ObserverSpec",
    "OBSERVER_KINDS",
    "GAIN_KINDS",
    "DISTURBANCE_KIND",
    "HYSTERESIS_KINDS",
    "N_GAINS",
]

#: The observers that run on gains (the UKF runs on its noise model).
GAIN_KINDS = GAIN_OBSERVERS
#: The built-in observers.
OBSERVER_KINDS = (*GAIN_KINDS, "ukf")
#: The disturbance observer: four states, the law sees the lumped ``x3hat + dhat``.
DISTURBANCE_KIND = "phdo"
#: The observers with the hysteresis model (x3 estimated through it).
HYSTERESIS_KINDS = ("phso", DISTURBANCE_KIND)
#: The number of continuous gains each kind takes.
N_GAINS = {kind: 4 if kind == DISTURBANCE_KIND else 3 for kind in GAIN_KINDS}


@dataclass(frozen=True)
class ObserverSpec:
    """The observer of a loop: its kind and its gains.

    Parameters
    ----------
    kind : {"phso", "eso", "phdo", "ukf", "custom"}
    gains : tuple of float, optional
        Continuous gains in the kind's own shape: ``(l1, l2, l3)`` (1/s, 1/s^2, 1/s)
        for the PHSO and the ESO, ``(l1, l2, l3, l4)`` for the PHDO; ``None`` for the
        UKF and a custom observer.
    udot_max : float, optional
        The UKF's input-rate envelope (input unit/s) for its process noise; when
        ``None`` a simulation derives it from the reference.
    custom : object or callable, optional
        A custom observer (kind ``"custom"``): an object with ``predict(u)``,
        ``update(z)`` and ``x`` (a simulation runs a copy), or a factory
        ``factory(params, dt)`` returning one.

    Raises
    ------
    InputError
        An unknown kind, or a field that does not belong to the kind.
    GainError
        Gains that are not the kind's number of finite numbers.
    """

    kind: str = "phso"
    gains: tuple[float, ...] | None = None
    udot_max: float | None = None
    custom: Any = None

    def __post_init__(self) -> None:
        kind = self.kind
        if kind not in (*OBSERVER_KINDS, "custom"):
            raise InputError(
                f"observer must be one of {', '.join(map(repr, OBSERVER_KINDS))} or a custom "
                f"observer, got {kind!r}"
            )
        if kind in GAIN_KINDS:
            if self.gains is None:
                names = ", ".join(f"l{i + 1}" for i in range(N_GAINS[kind]))
                raise InputError(f"the {kind.upper()} needs observer gains {names}")
            object.__setattr__(self, "gains", _gains(self.gains, N_GAINS[kind], kind))
        elif self.gains is not None:
            raise InputError(f"the {kind} observer takes no gains")
        if self.udot_max is not None:
            if kind != "ukf":
                raise InputError("udot_max belongs to the UKF's noise model only")
            object.__setattr__(
                self, "udot_max", real(self.udot_max, "udot_max (V/s)", within=UDOT_MAX)
            )
        if kind == "custom":
            obj = self.custom
            if not (callable(obj) or (hasattr(obj, "predict") and hasattr(obj, "update"))):
                raise InputError(
                    "a custom observer is an object with predict(u), update(z) and x, or a "
                    "factory factory(params, dt) returning one"
                )
        elif self.custom is not None:
            raise InputError(f"the {kind} observer is built in; custom= is for kind 'custom'")

    @classmethod
    def of(cls, kind: str, gains: Any = None, *, udot_max: float | None = None) -> ObserverSpec:
        """``kind`` running the design ``gains``: the PHDO given 3 gains runs ``(l1, l2, 0, l3)``.

        Four gains are taken as the PHDO's own; the PHSO and the ESO take three.
        """
        if kind == DISTURBANCE_KIND and gains is not None and len(_seq(gains)) == 3:
            gains = gains_for_observer(kind, gains)
        values = None if gains is None else tuple(_seq(gains))
        return cls(kind=kind, gains=values, udot_max=udot_max)

    @classmethod
    def from_custom(cls, observer: Any) -> ObserverSpec:
        """A user's observer object or factory (see the class docstring)."""
        return cls(kind="custom", custom=observer)

    @property
    def four_state(self) -> bool:
        """The disturbance observer: four states ``(x1, x2, x3, d)``, the law sees ``x3 + d``."""
        return self.kind == DISTURBANCE_KIND

    @property
    def hysteresis_model(self) -> bool:
        """The observer estimates ``x3`` through the hysteresis model (PHSO, PHDO)."""
        return self.kind in HYSTERESIS_KINDS

    @property
    def label(self) -> str:
        """``PHSO``, ``ESO``, ``PHDO``, ``UKF`` or the custom observer's class name."""
        if self.kind != "custom":
            return self.kind.upper()
        obj = self.custom
        return getattr(obj, "kind", None) or getattr(obj, "__name__", type(obj).__name__)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind if self.kind != "custom" else self.label,
            "gains": None if self.gains is None else list(self.gains),
            "udot_max": self.udot_max,
        }


def _seq(gains: Any) -> list[Any]:
    try:
        return list(gains)
    except TypeError:
        raise GainError(f"gains must be a sequence of numbers, got {gains!r}") from None


def _gains(gains: Any, n: int, kind: str) -> tuple[float, ...]:
    values = _seq(gains)
    if len(values) != n:
        raise GainError(f"the {kind.upper()} takes {n} gains, got {len(values)}: {gains!r}")
    return tuple(real(g, f"gains[{i}]", within=GAIN, error=GainError) for i, g in enumerate(values))
