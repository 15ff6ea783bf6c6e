"""Parameter uncertainty of a stage: one box type for the stage file, the command line and Python.

The ``[uncertainty]`` section of a stage file::

    [uncertainty]
    source = "identified"     # or "specified"; optional
    level = 0.95              # confidence level of the half-widths; optional
    a1 = { rel = 0.02 }       # per parameter (a1, a2, a3, alpha, beta, gamma):
    alpha = { abs = 0.01 }    # a relative half-width (fraction of the nominal) or an
                              # absolute one (the parameter's unit), not both;
                              # an unlisted parameter is exact

and the same box as text (``bwdesign sweep --uncertainty``, :meth:`UncertaintyBox.parse`):
``"a1=2%,alpha=0.01"`` (``2%`` relative, ``0.01`` absolute).

A half-width may be ``inf`` (TOML ``inf``): the parameter is not determined
(an identification that could not see it). Such a box has bounds but refuses
to give vertices or samples until a finite range is specified.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import BWDesignError, ConfigError, InputError, ParameterError
from ..validate import NONNEGATIVE, Range, parse_real, real
from .params import MODEL_FIELDS, BoucWenParams

__all__ = ["UncertaintyBox", "DisturbanceBound", "disturbance_bounds"]

_KINDS = ("rel", "abs")
_SOURCES = ("identified", "specified")
_WIDTH = Range(0.0, math.inf)


def _clean(
    widths: dict[str, Any], error: type[BWDesignError], where: str
) -> dict[str, tuple[str, float]]:
    """``widths`` checked, as floats in :data:`MODEL_FIELDS` order, or raise ``error``."""
    clean = {}
    for name, spec in widths.items():
        if name not in MODEL_FIELDS:
            raise error(f"{where}: unknown parameter {name!r}; use {', '.join(MODEL_FIELDS)}")
        try:
            kind, value = spec
        except (TypeError, ValueError):
            raise error(
                f'{where} {name}: expected ("rel" | "abs", half-width), got {spec!r}'
            ) from None
        if kind not in _KINDS:
            raise error(f"{where} {name}: kind must be rel or abs, got {kind!r}")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise error(f"{where} {name}.{kind} must be a number, got {value!r}")
        if math.isnan(value) or value < 0:
            raise error(f"{where} {name}.{kind} must be >= 0, got {value!r}")
        clean[name] = (kind, float(value))
    return {n: clean[n] for n in MODEL_FIELDS if n in clean}


def _check_meta(source: Any, level: Any, error: type[BWDesignError], where: str) -> None:
    if source is not None and source not in _SOURCES:
        raise error(f"{where} source must be one of {', '.join(_SOURCES)}, got {source!r}")
    if level is not None and (
        isinstance(level, bool) or not isinstance(level, int | float) or not 0 < level < 1
    ):
        raise error(f"{where} level must be a number in (0, 1), got {level!r}")


@dataclass(frozen=True)
class UncertaintyBox:
    """Per-parameter half-widths around a nominal :class:`BoucWenParams`.

    Build it from a stage file's table (:meth:`from_dict`, what
    :func:`bwdesign.load_config` does), from text (:meth:`parse`) or directly.
    Its bounds for given parameters are :meth:`bounds`; :meth:`check` is the
    one test that every corner is a usable plant.

    Errors, one rule: a box that cannot be built raises :class:`ConfigError`
    when it comes from a stage file (:meth:`from_dict`) and :class:`InputError`
    when it comes from the command line or Python (:meth:`parse`, the
    constructor); a box that is well formed but does not fit the parameters it
    is applied to (:meth:`check`, and so :meth:`vertices` and :meth:`sample`)
    raises :class:`ParameterError`, wherever it came from: a corner is then
    not a usable model. The command line prints either as one ``error:`` line
    (exit 2).

    Parameters
    ----------
    widths : dict
        ``{name: ("rel" | "abs", half_width)}`` for names among a1, a2, a3,
        alpha, beta, gamma; ``half_width >= 0`` (``inf`` = not determined).
    source : {"identified", "specified"} or None
    level : float or None
        Confidence level in (0, 1) when the half-widths are confidence intervals.

    Examples
    --------
    >>> from bwdesign import preset
    >>> box = UncertaintyBox.parse("a1=2%,alpha=0.01")
    >>> box.widths
    {'a1': ('rel', 0.02), 'alpha': ('abs', 0.01)}
    >>> box.describe(preset("paper_experiment"))
    'a1 in [156631, 163024], alpha in [0.4695, 0.4895]'
    """

    widths: dict[str, tuple[str, float]] = field(default_factory=dict)
    source: str | None = None
    level: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.widths, Mapping):
            raise InputError(
                "UncertaintyBox widths must be a mapping {name: (kind, half_width)}, "
                f"got {self.widths!r}"
            )
        clean = _clean(dict(self.widths), InputError, "UncertaintyBox")
        object.__setattr__(self, "widths", clean)
        _check_meta(self.source, self.level, InputError, "UncertaintyBox")
        if self.level is not None:
            object.__setattr__(self, "level", float(self.level))

    # -- construction -----------------------------------------------------
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
        allowed = {"source", "level", "disturbance", *MODEL_FIELDS}
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
        widths = _clean(widths, ConfigError, "[uncertainty]")
        _check_meta(data.get("source"), data.get("level"), ConfigError, "[uncertainty]")
        return cls(widths=widths, source=data.get("source"), level=data.get("level"))

    @classmethod
    def parse(cls, text: str, *, name: str = "uncertainty") -> UncertaintyBox:
        """The box written as text: ``"a1=2%,alpha=0.01"``.

        Comma-separated ``NAME=WIDTH`` items, ``NAME`` among a1, a2, a3, alpha,
        beta, gamma, each once; ``WIDTH`` a finite number >= 0, relative to the
        nominal with ``%`` (``2%`` = 0.02 of it), absolute (the parameter's unit)
        without. ``name`` starts every message (``"--uncertainty"`` on the
        command line).

        Raises
        ------
        InputError
            An item that is not ``NAME=WIDTH`` with a known name, a width that
            is not a finite number >= 0, a name given twice, no item at all.
        """
        if not isinstance(text, str):
            raise InputError(f"{name}: expected text such as 'a1=2%,alpha=0.01', got {text!r}")
        out: dict[str, tuple[str, float]] = {}
        for item in filter(None, (s.strip() for s in text.split(","))):
            key, sep, value = item.partition("=")
            key, value = key.strip(), value.strip()
            if not sep or key not in MODEL_FIELDS:
                raise InputError(
                    f"{name}: expected NAME=WIDTH with NAME in {', '.join(MODEL_FIELDS)} "
                    f"(WIDTH as 2% relative or 0.01 absolute), got {item!r}"
                )
            rel = value.endswith("%")
            what = f"{name}: {key} half-width{' (%)' if rel else ''}"
            w = parse_real(value[:-1] if rel else value, what, within=_WIDTH)
            if key in out:
                raise InputError(
                    f"{name}: {key} given twice ({_width_text(out[key])} and {value}); "
                    "give each parameter once"
                )
            out[key] = ("rel", w / 100) if rel else ("abs", w)
        if not out:
            raise InputError(f"{name}: no parameter given")
        return cls(widths=out)

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

    # -- the box around given parameters ----------------------------------
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

    def describe(self, params: BoucWenParams) -> str:
        """``"a1 in [156631, 163024], alpha in [0.4695, 0.4895]"``: the varied parameters."""
        return ", ".join(
            f"{k} in [{lo:.6g}, {hi:.6g}]"
            for k, (lo, hi) in self.bounds(params).items()
            if lo != hi
        )

    def undetermined(self) -> tuple[str, ...]:
        """Parameters with an infinite half-width."""
        return tuple(n for n, (_, v) in self.widths.items() if math.isinf(v))

    def check(
        self, params: BoucWenParams, *, bounded: bool = True
    ) -> dict[str, tuple[float, float]]:
        """The bounds of the parameters the box varies, after checking every corner is usable.

        Usable: every half-width is finite; each varied parameter's low and high
        end is a valid model parameter (:class:`BoucWenParams`: a1 > 0, a2 >= 0,
        alpha > 0, the supported ranges) and a3 keeps its sign; with ``bounded``
        (the default) every corner is in the bounded class (alpha > 0,
        beta + gamma > 0, beta - gamma >= 0). Each condition is an interval per
        parameter or linear in the parameters, so the corners decide for the
        whole box. ``bounded=False`` leaves the bounded class to the caller (a
        robust observer certificate answers "no" for such a box).

        Returns
        -------
        dict
            ``{name: (low, high)}`` for the parameters with ``low < high``,
            in the order a1, a2, a3, alpha, beta, gamma.

        Raises
        ------
        ParameterError
            A parameter not determined (infinite half-width), a corner that is
            not a valid model, or (with ``bounded``) one outside the bounded
            class; ``field`` names the parameter.
        """
        bad = self.undetermined()
        if bad:
            raise ParameterError(
                f"the uncertainty box leaves {', '.join(bad)} not determined (infinite "
                f"half-width): give a finite range for {'them' if len(bad) > 1 else 'it'} "
                "([uncertainty] in a stage file, --uncertainty on the command line)",
                field=bad[0],
            )
        b = self.bounds(params)
        for name in MODEL_FIELDS:
            lo, hi = b[name]
            if lo == hi:
                continue
            if name == "a3" and lo <= 0 <= hi:
                raise ParameterError(
                    f"the uncertainty box lets a3 reach 0 (a3 in [{lo:.6g}, {hi:.6g}]); "
                    "a3 must keep its sign: narrow the box",
                    field="a3",
                )
            for end in (lo, hi):
                try:
                    params.replace(**{name: end, "name": ""})
                except ParameterError as err:
                    why = str(err).removeprefix("BoucWenParams: ")
                    raise ParameterError(
                        f"the uncertainty box lets {name} reach {end:.6g}, not a usable "
                        f"plant ({why}): narrow the box",
                        field=name,
                    ) from None
        if bounded:
            _require_bounded_corners(b)
        return {k: (float(lo), float(hi)) for k, (lo, hi) in b.items() if lo != hi}

    def _build(self, params: BoucWenParams, values: dict[str, float], label: str) -> BoucWenParams:
        return params.replace(**values, name=f"{params.name}{label}")

    def vertices(self, params: BoucWenParams) -> list[BoucWenParams]:
        """The ``2^k`` corners over the ``k`` uncertain parameters (nominal if none).

        Raises :class:`ParameterError` as :meth:`check` with ``bounded=False``.
        """
        b = self.check(params, bounded=False)
        out = []
        for i, corner in enumerate(itertools.product((0, 1), repeat=len(b))):
            vals = {n: b[n][c] for n, c in zip(b, corner, strict=True)}
            out.append(self._build(params, vals, f"/vertex{i}"))
        return out

    def sample(
        self, params: BoucWenParams, rng: np.random.Generator, n: int
    ) -> list[BoucWenParams]:
        """``n`` plants drawn uniformly in the box (``rng = np.random.default_rng(seed)``).

        Raises :class:`ParameterError` as :meth:`check` with ``bounded=False``.
        """
        self.check(params, bounded=False)
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


def _width_text(spec: tuple[str, float]) -> str:
    kind, w = spec
    return f"{100 * w:g}%" if kind == "rel" else f"{w:g}"


def _require_bounded_corners(b: dict[str, tuple[float, float]]) -> None:
    """Raise :class:`ParameterError` at the first (alpha, beta, gamma) corner outside the class.

    Its ``field`` is the first parameter of the failed condition that the box varies.
    """
    varied = [n for n in ("alpha", "beta", "gamma") if b[n][0] != b[n][1]]
    for a, be, ga in itertools.product(b["alpha"], b["beta"], b["gamma"]):
        for cond, value, strict, names in (
            ("alpha > 0", a, True, ("alpha",)),
            ("beta + gamma > 0", be + ga, True, ("beta", "gamma")),
            ("beta - gamma >= 0", be - ga, False, ("beta", "gamma")),
        ):
            if value < 0 or (strict and value == 0):
                name = next((n for n in names if n in varied), names[0])
                raise ParameterError(
                    f"the uncertainty box leaves the bounded class: at its corner alpha = "
                    f"{a:.6g}, beta = {be:.6g}, gamma = {ga:.6g}, {cond} is {value:.6g}; "
                    "narrow the box",
                    field=name,
                )


@dataclass(frozen=True)
class DisturbanceBound:
    """What the model does not explain, as a slowly varying input-equivalent disturbance.

    The plant is taken as ``x2' = -a1 x1 - a2 x2 - a1 x3 + a3 (u + d)`` with
    ``|d(t)| <= input_max`` and ``|d'(t)| <= rate_max``: creep, an amplifier lag, drift
    or a second mode that the Bouc-Wen model misses, in the input's unit. The observers,
    certificates and firmware keep the Bouc-Wen model; ``d`` is what they must tolerate.
    Stage file::

        [uncertainty.disturbance]
        input_max = 0.35      # |d| <= input_max (input unit)
        rate_max = 2.0        # |d'| <= rate_max (input unit/s)
        source = "identified" # or "specified"

    Parameters
    ----------
    input_max : float
        Bound on ``|d|`` (input unit), finite and >= 0.
    rate_max : float
        Bound on ``|d'|`` (input unit/s), finite and >= 0.
    source : {"identified", "specified"}

    Raises
    ------
    InputError
        A bound that is not a finite number >= 0, or an unknown source
        (:meth:`from_dict` raises ``ConfigError`` for a stage file's table).
    """

    input_max: float
    rate_max: float
    source: str = "specified"

    def __post_init__(self) -> None:
        self._check(InputError, "DisturbanceBound")

    def _check(self, error: type[BWDesignError], where: str) -> None:
        for name in ("input_max", "rate_max"):
            value = real(getattr(self, name), f"{where} {name}", within=NONNEGATIVE, error=error)
            object.__setattr__(self, name, value)
        if self.source not in _SOURCES:
            raise error(f"{where} source must be one of {', '.join(_SOURCES)}, got {self.source!r}")

    @property
    def none(self) -> bool:
        """Both bounds are 0: the model is taken to explain the stage."""
        return self.input_max == 0 and self.rate_max == 0

    @classmethod
    def from_dict(cls, data: Any) -> DisturbanceBound:
        """Build from a parsed ``[uncertainty.disturbance]`` table (strict keys and types)."""
        where = "[uncertainty.disturbance]"
        if not isinstance(data, dict):
            raise ConfigError(f"{where} must be a table, got {type(data).__name__}")
        allowed = {"input_max", "rate_max", "source"}
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise ConfigError(
                f"{where}: unknown key(s) {', '.join(unknown)}; allowed keys are "
                f"{', '.join(sorted(allowed))}"
            )
        missing = [k for k in ("input_max", "rate_max") if k not in data]
        if missing:
            raise ConfigError(f"{where}: missing {', '.join(missing)}")
        try:
            return cls(data["input_max"], data["rate_max"], data.get("source", "specified"))
        except InputError as err:
            raise ConfigError(str(err).replace("DisturbanceBound", where)) from None

    def to_dict(self) -> dict[str, Any]:
        return {"input_max": self.input_max, "rate_max": self.rate_max, "source": self.source}

    def to_toml(self) -> str:
        """The ``[uncertainty.disturbance]`` table as stage-file text."""
        return (
            "[uncertainty.disturbance]\n"
            f"input_max = {self.input_max!r}\n"
            f"rate_max = {self.rate_max!r}\n"
            f'source = "{self.source}"\n'
        )


def disturbance_bounds(disturbance: Any) -> tuple[float, float]:
    """``(input_max, rate_max)`` of an optional :class:`DisturbanceBound`; ``(0, 0)`` for None.

    Raises
    ------
    InputError
        ``disturbance`` is neither None nor a DisturbanceBound.
    """
    if disturbance is None:
        return (0.0, 0.0)
    if not isinstance(disturbance, DisturbanceBound):
        raise InputError(
            f"disturbance must be a DisturbanceBound or None, got {type(disturbance).__name__}"
        )
    return (disturbance.input_max, disturbance.rate_max)
