"""Parameter uncertainty of a stage: the ``[uncertainty]`` section of a stage file.

::

    [uncertainty]
    source = "identified"     # or "specified"; optional
    level = 0.95              # confidence level of the half-widths; optional
    a1 = { rel = 0.02 }       # per parameter (a1, a2, a3, alpha, beta, gamma):
    alpha = { abs = 0.01 }    # a relative half-width (fraction of the nominal) or an
                              # absolute one (the parameter's unit), not both;
                              # an unlisted parameter is exact

A half-width may be ``inf`` (TOML ``inf``): the parameter is not determined
(an identification that could not see it). Such a box has bounds but refuses
to give vertices or samples until a finite range is specified.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ConfigError, ParameterError
from .params import MODEL_FIELDS, BoucWenParams

__all__ = ["UncertaintyBox", "BoxCheck"]

_KINDS = ("rel", "abs")
_SOURCES = ("identified", "specified")


@dataclass(frozen=True)
class BoxCheck:
    """Which corners of a box leave the bounded class.

    Attributes
    ----------
    bounded : bool
        Every vertex is in the bounded class.
    outside : tuple of (dict, str)
        For each offending vertex: its (beta, gamma, alpha) values and the reason.
    """

    bounded: bool
    outside: tuple[tuple[dict[str, float], str], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "bounded": self.bounded,
            "outside": [{"vertex": v, "reason": r} for v, r in self.outside],
        }


@dataclass(frozen=True)
class UncertaintyBox:
    """Per-parameter half-widths around a nominal :class:`BoucWenParams`.

    Parameters
    ----------
    widths : dict
        ``{name: ("rel" | "abs", half_width)}`` for names among a1, a2, a3,
        alpha, beta, gamma; ``half_width >= 0`` (``inf`` = not determined).
    source : {"identified", "specified"} or None
    level : float or None
        Confidence level in (0, 1) when the half-widths are confidence intervals.
    """

    widths: dict[str, tuple[str, float]] = field(default_factory=dict)
    source: str | None = None
    level: float | None = None

    def __post_init__(self) -> None:
        clean = {}
        for name, spec in dict(self.widths).items():
            if name not in MODEL_FIELDS:
                raise ConfigError(
                    f"[uncertainty]: unknown parameter {name!r}; use {', '.join(MODEL_FIELDS)}"
                )
            kind, value = spec
            if kind not in _KINDS:
                raise ConfigError(f"[uncertainty] {name}: kind must be rel or abs, got {kind!r}")
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(f"[uncertainty] {name}.{kind} must be a number, got {value!r}")
            if math.isnan(value) or value < 0:
                raise ConfigError(f"[uncertainty] {name}.{kind} must be >= 0, got {value!r}")
            clean[name] = (kind, float(value))
        object.__setattr__(self, "widths", {n: clean[n] for n in MODEL_FIELDS if n in clean})
        if self.source is not None and self.source not in _SOURCES:
            raise ConfigError(
                f"[uncertainty] source must be one of {', '.join(_SOURCES)}, got {self.source!r}"
            )
        if self.level is not None:
            lv = self.level
            if isinstance(lv, bool) or not isinstance(lv, int | float) or not 0 < lv < 1:
                raise ConfigError(f"[uncertainty] level must be a number in (0, 1), got {lv!r}")
            object.__setattr__(self, "level", float(lv))

    @classmethod
    def from_dict(cls, data: Any) -> UncertaintyBox:
        """Build from a parsed ``[uncertainty]`` table (strict keys and types).

        Raises
        ------
        ConfigError
            Unknown key, a parameter entry that is not ``{rel = x}`` or
            ``{abs = x}``, a negative or non-numeric half-width, a bad
            ``source`` or ``level``.
        """
        if not isinstance(data, dict):
            raise ConfigError(f"[uncertainty] must be a table, got {type(data).__name__}")
        allowed = {"source", "level", *MODEL_FIELDS}
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise ConfigError(
                f"[uncertainty]: unknown key(s) {', '.join(unknown)}; allowed keys are "
                f"{', '.join(sorted(allowed))}"
            )
        widths = {}
        for name in MODEL_FIELDS:
            if name not in data:
                continue
            entry = data[name]
            if not isinstance(entry, dict):
                raise ConfigError(
                    f"[uncertainty] {name} must be a table {{ rel = x }} or {{ abs = x }}, "
                    f"got {entry!r}"
                )
            keys = set(entry)
            if keys - set(_KINDS) or len(keys) != 1:
                raise ConfigError(
                    f"[uncertainty] {name}: give exactly one of rel (fraction of the nominal) "
                    f"or abs (absolute half-width), got keys {', '.join(sorted(keys)) or 'none'}"
                )
            (kind,) = keys
            widths[name] = (kind, entry[kind])
        return cls(widths=widths, source=data.get("source"), level=data.get("level"))

    def to_toml(self) -> str:
        """The ``[uncertainty]`` section, read back exactly by :meth:`from_dict`."""
        lines = ["[uncertainty]"]
        if self.source is not None:
            lines.append(f'source = "{self.source}"')
        if self.level is not None:
            lines.append(f"level = {self.level!r}")
        for name, (kind, value) in self.widths.items():
            text = "inf" if math.isinf(value) else repr(value)
            lines.append(f"{name} = {{ {kind} = {text} }}")
        return "\n".join(lines) + "\n"

    def half_width(self, name: str, params: BoucWenParams) -> float:
        """Half-width of ``name`` in the parameter's own unit (0 when unlisted)."""
        if name not in MODEL_FIELDS:
            raise ParameterError(f"unknown parameter {name!r}", field=name)
        if name not in self.widths:
            return 0.0
        kind, value = self.widths[name]
        return value * abs(getattr(params, name)) if kind == "rel" else value

    def bounds(self, params: BoucWenParams) -> dict[str, tuple[float, float]]:
        """``{name: (low, high)}`` for every parameter (equal ends when exact)."""
        out = {}
        for name in MODEL_FIELDS:
            v, hw = getattr(params, name), self.half_width(name, params)
            out[name] = (v - hw, v + hw)
        return out

    def undetermined(self) -> tuple[str, ...]:
        """Parameters with an infinite half-width."""
        return tuple(n for n, (_, v) in self.widths.items() if math.isinf(v))

    def _require_finite(self, what: str) -> None:
        bad = self.undetermined()
        if bad:
            raise ParameterError(
                f"cannot take {what} of the uncertainty box: {', '.join(bad)} "
                "not determined (infinite half-width); specify a finite range for "
                f"{'them' if len(bad) > 1 else 'it'} in [uncertainty]",
                field=bad[0],
            )

    def _build(self, params: BoucWenParams, values: dict[str, float], label: str) -> BoucWenParams:
        try:
            return params.replace(**values, name=f"{params.name}{label}")
        except ParameterError as err:
            raise ParameterError(
                f"the uncertainty box reaches a non-physical plant: {err}", field=err.field
            ) from None

    def vertices(self, params: BoucWenParams) -> list[BoucWenParams]:
        """The ``2^k`` corners over the ``k`` uncertain parameters (nominal if none)."""
        self._require_finite("the vertices")
        b = self.bounds(params)
        names = [n for n in MODEL_FIELDS if b[n][0] != b[n][1]]
        out = []
        for i, corner in enumerate(itertools.product((0, 1), repeat=len(names))):
            vals = {n: b[n][c] for n, c in zip(names, corner, strict=True)}
            out.append(self._build(params, vals, f"/vertex{i}"))
        return out

    def sample(
        self, params: BoucWenParams, rng: np.random.Generator, n: int
    ) -> list[BoucWenParams]:
        """``n`` plants drawn uniformly in the box (``rng = np.random.default_rng(seed)``)."""
        self._require_finite("samples")
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise ParameterError(f"n must be an integer >= 0, got {n!r}")
        b = self.bounds(params)
        lo = np.array([b[k][0] for k in MODEL_FIELDS])
        hi = np.array([b[k][1] for k in MODEL_FIELDS])
        draws = rng.uniform(lo, hi, size=(n, len(MODEL_FIELDS)))
        return [
            self._build(params, dict(zip(MODEL_FIELDS, map(float, row), strict=True)), f"/s{i}")
            for i, row in enumerate(draws)
        ]

    def check(self, params: BoucWenParams) -> BoxCheck:
        """Which vertices of the (alpha, beta, gamma) box leave the bounded class.

        The class conditions (alpha > 0, beta + gamma > 0, beta - gamma >= 0) are
        linear in the parameters, so the box is inside iff all its corners are.
        """
        b = self.bounds(params)
        outside = []
        for a, be, ga in itertools.product(b["alpha"], b["beta"], b["gamma"]):
            reasons = []
            if not a > 0:
                reasons.append(f"alpha = {a:.6g} <= 0")
            if not be + ga > 0:
                reasons.append(f"beta + gamma = {be + ga:.6g} <= 0")
            if not be - ga >= 0:
                reasons.append(f"beta - gamma = {be - ga:.6g} < 0")
            if reasons:
                outside.append(({"alpha": a, "beta": be, "gamma": ga}, "; ".join(reasons)))
        uniq = tuple(dict.fromkeys((tuple(v.items()), r) for v, r in outside))
        return BoxCheck(bounded=not uniq, outside=tuple((dict(v), r) for v, r in uniq))
