"""Bouc-Wen actuator parameters: the model of docs/design.md, section "The model".

The state-space form used everywhere in bwdesign (paper eq. 2)::

    x1' = x2
    x2' = -a1 x1 - a2 x2 - a1 x3 + a3 u
    x3' = alpha u' - beta |u'| x3 - gamma u' |x3|
    y   = x1

with the physical model ``m x'' + b x' + k x = k (d u - h)`` and
``h' = alpha0 d u' - beta |u'| h - gamma u' |h|`` giving ``a1 = k/m``,
``a2 = b/m``, ``a3 = k d/m`` and ``alpha = alpha0 d``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

from ..errors import ParameterError, UnboundedModelError
from ..validate import Range, real

__all__ = [
    "BoucWenParams",
    "PhysicalParams",
    "BoundedClassVerdict",
    "PRESETS",
    "preset",
    "require_bounded",
    "PARAM_RANGES",
    "PHYSICAL_RANGES",
]

MODEL_FIELDS = ("a1", "a2", "a3", "alpha", "beta", "gamma")
PHYSICAL_FIELDS = ("m", "b", "k", "d", "alpha0")


#: Supported range of each model parameter. Wide enough for every real stage
#: (a1 = k/m from 1e-6 to 1e12 1/s^2 is a resonance from 0.16 mHz to 160 kHz);
#: narrow enough that no product, quotient or exponential inside bwdesign
#: overflows. ``a3`` may have either sign; ``|a3|`` must lie in ``A3_MAGNITUDE``.
PARAM_RANGES: dict[str, Range] = {
    "a1": Range(1e-6, 1e12, unit="1/s^2"),
    "a2": Range(0.0, 1e9, unit="1/s"),
    "a3": Range(-1e15, 1e15),
    "alpha": Range(1e-9, 1e6),
    "beta": Range(-1e6, 1e6, unit="1/V"),
    "gamma": Range(-1e6, 1e6, unit="1/V"),
}
A3_MAGNITUDE = Range(1e-9, 1e15)
#: Supported range of each physical quantity (their quotients then stay finite).
PHYSICAL_RANGES: dict[str, Range] = {
    "m": Range(1e-12, 1e12),
    "b": Range(0.0, 1e12),
    "k": Range(1e-12, 1e12),
    "d": Range(-1e12, 1e12),
    "alpha0": Range(-1e12, 1e12),
}


def _number(value: Any, name: str, owner: str, within: Range | None = None) -> float:
    """Return ``value`` as a finite float (in ``within``) or raise :class:`ParameterError`."""
    return real(value, f"{owner}: {name}", within=within, error=ParameterError)


@dataclass(frozen=True, kw_only=True)
class PhysicalParams:
    """Physical quantities of paper eq. (1), kept when a plant is built from them.

    Parameters
    ----------
    m : float
        Effective mass (kg, or any unit consistent with ``k`` and ``b``).
    b : float
        Damping constant (N s/m in the same unit system).
    k : float
        Stiffness (N/m).
    d : float
        Piezo coefficient: displacement per volt (µm/V).
    alpha0 : float
        Hysteresis amplitude factor; ``alpha = alpha0 d``.
    """

    m: float
    b: float
    k: float
    d: float
    alpha0: float

    def __post_init__(self) -> None:
        for f in PHYSICAL_FIELDS:
            object.__setattr__(self, f, _number(getattr(self, f), f, "PhysicalParams"))
        if self.m <= 0:
            raise ParameterError(f"PhysicalParams: m must be > 0, got {self.m}", field="m")
        if self.k <= 0:
            raise ParameterError(f"PhysicalParams: k must be > 0, got {self.k}", field="k")
        if self.b < 0:
            raise ParameterError(f"PhysicalParams: b must be >= 0, got {self.b}", field="b")
        for f in PHYSICAL_FIELDS:
            _number(getattr(self, f), f, "PhysicalParams", PHYSICAL_RANGES[f])


@dataclass(frozen=True)
class BoundedClassVerdict:
    """Whether the hysteresis state stays bounded for every input.

    Attributes
    ----------
    bounded : bool
        True when alpha > 0, beta + gamma > 0 and beta - gamma >= 0
        (Ikhouane-Rodellar class for n = 1).
    reason : str
        One sentence naming the condition that holds or fails.
    h_max : float
        The hysteresis bound alpha/(beta + gamma) (plant length unit) when
        bounded, ``inf`` otherwise.
    """

    bounded: bool
    reason: str
    h_max: float

    def to_dict(self) -> dict[str, Any]:
        return {"bounded": self.bounded, "reason": self.reason, "h_max": self.h_max}


@dataclass(frozen=True, kw_only=True)
class BoucWenParams:
    """Parameters of the Bouc-Wen actuator model (paper eq. 2).

    Parameters
    ----------
    a1 : float
        Stiffness over mass, k/m (1/s^2). Must be > 0.
    a2 : float
        Damping over mass, b/m (1/s). Must be >= 0.
    a3 : float
        Input gain, k d/m (length unit per volt per s^2). Must be non-zero.
    alpha : float
        Hysteresis gain alpha0 d (length unit per volt). Must be > 0.
    beta, gamma : float
        Hysteresis shape parameters (1/V).
    name : str
        Label used in reports.
    length_unit, input_unit : str
        Units of x1 (and x3) and of u.
    physical : PhysicalParams or None
        The physical quantities, when the plant was built from them.

    Raises
    ------
    ParameterError
        A value is non-numeric, non-finite or out of range; ``err.field`` names it.

    Examples
    --------
    >>> p = BoucWenParams(a1=159827.5, a2=713.8, a3=222665.02,
    ...                   alpha=0.4795, beta=0.3762, gamma=0.0378)
    >>> p.bounded_class().bounded
    True
    """

    a1: float
    a2: float
    a3: float
    alpha: float
    beta: float
    gamma: float
    name: str = ""
    length_unit: str = "um"
    input_unit: str = "V"
    physical: PhysicalParams | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        owner = f"BoucWenParams {self.name!r}" if self.name else "BoucWenParams"
        for f in MODEL_FIELDS:
            object.__setattr__(self, f, _number(getattr(self, f), f, owner))
        if self.a1 <= 0:
            raise ParameterError(f"{owner}: a1 = k/m must be > 0, got {self.a1}", field="a1")
        if self.a2 < 0:
            raise ParameterError(f"{owner}: a2 = b/m must be >= 0, got {self.a2}", field="a2")
        if self.a3 == 0:
            raise ParameterError(f"{owner}: a3 = k d/m must be non-zero, got 0", field="a3")
        if self.alpha <= 0:
            raise ParameterError(f"{owner}: alpha must be > 0, got {self.alpha}", field="alpha")
        for f in MODEL_FIELDS:
            _number(getattr(self, f), f, owner, PARAM_RANGES[f])
        if abs(self.a3) not in A3_MAGNITUDE:
            raise ParameterError(
                f"{owner}: |a3| = {abs(self.a3):g} is outside the supported range "
                f"{A3_MAGNITUDE.text()}",
                field="a3",
            )
        for f in ("name", "length_unit", "input_unit"):
            if not isinstance(getattr(self, f), str):
                raise ParameterError(f"{owner}: {f} must be a string", field=f)

    # -- construction -----------------------------------------------------
    @classmethod
    def from_physical(
        cls,
        *,
        m: float,
        b: float,
        k: float,
        d: float,
        alpha0: float,
        beta: float,
        gamma: float,
        name: str = "",
        length_unit: str = "um",
        input_unit: str = "V",
    ) -> BoucWenParams:
        """Build the model from the physical quantities of paper eq. (1).

        ``a1 = k/m``, ``a2 = b/m``, ``a3 = k d/m``, ``alpha = alpha0 d``.
        """
        phys = PhysicalParams(m=m, b=b, k=k, d=d, alpha0=alpha0)
        return cls(
            a1=phys.k / phys.m,
            a2=phys.b / phys.m,
            a3=phys.k * phys.d / phys.m,
            alpha=phys.alpha0 * phys.d,
            beta=beta,
            gamma=gamma,
            name=name,
            length_unit=length_unit,
            input_unit=input_unit,
            physical=phys,
        )

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, owner: str = "[plant]") -> BoucWenParams:
        """Build from a ``[plant]`` table: model form or physical form, not both.

        Raises
        ------
        ParameterError
            Unknown keys, a missing field, or both forms mixed.
        """
        if not isinstance(data, dict):
            raise ParameterError(f"{owner} must be a table, got {type(data).__name__}")
        meta = {"name", "length_unit", "input_unit"}
        model_keys = set(MODEL_FIELDS) | meta
        phys_keys = set(PHYSICAL_FIELDS) | {"beta", "gamma"} | meta
        allowed = model_keys | phys_keys
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise ParameterError(
                f"{owner}: unknown key(s) {', '.join(unknown)}; allowed keys are "
                f"{', '.join(sorted(allowed))}",
                field=unknown[0],
            )
        has_model = any(k in data for k in ("a1", "a2", "a3", "alpha"))
        has_phys = any(k in data for k in PHYSICAL_FIELDS)
        if has_model and has_phys:
            raise ParameterError(
                f"{owner}: give either a1, a2, a3, alpha or m, b, k, d, alpha0, not both"
            )
        required = (*PHYSICAL_FIELDS, "beta", "gamma") if has_phys else MODEL_FIELDS
        missing = [k for k in required if k not in data]
        if missing:
            raise ParameterError(
                f"{owner}: missing field(s) {', '.join(missing)}", field=missing[0]
            )
        kwargs = {k: data[k] for k in data}
        if has_phys:
            return cls.from_physical(**kwargs)
        return cls(**kwargs)

    # -- views -------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain dict for JSON/TOML (model form, plus the physical form when known)."""
        out: dict[str, Any] = {"name": self.name}
        out.update({f: getattr(self, f) for f in MODEL_FIELDS})
        out["length_unit"] = self.length_unit
        out["input_unit"] = self.input_unit
        if self.physical is not None:
            out["physical"] = asdict(self.physical)
        return out

    def to_toml(self) -> str:
        """A ``[plant]`` table that :func:`bwdesign.load_plant` reads back exactly."""
        lines = ["[plant]"]
        lines.append(f"name = {_toml_str(self.name)}")
        if self.physical is not None:
            for f in PHYSICAL_FIELDS:
                lines.append(f"{f} = {getattr(self.physical, f)!r}")
            lines.append(f"beta = {self.beta!r}")
            lines.append(f"gamma = {self.gamma!r}")
        else:
            for f in MODEL_FIELDS:
                lines.append(f"{f} = {getattr(self, f)!r}")
        lines.append(f"length_unit = {_toml_str(self.length_unit)}")
        lines.append(f"input_unit = {_toml_str(self.input_unit)}")
        return "\n".join(lines) + "\n"

    def bounded_class(self) -> BoundedClassVerdict:
        """Check alpha > 0, beta + gamma > 0, beta - gamma >= 0 (n = 1).

        Under these conditions the hysteresis state stays in
        ``|x3| <= max(|x3(0)|, alpha/(beta + gamma))`` for every input.
        """
        s, d = self.beta + self.gamma, self.beta - self.gamma
        if s <= 0:
            return BoundedClassVerdict(
                False,
                f"beta + gamma = {s:.6g} <= 0: x3 grows without bound on a monotone "
                "input (it has no equilibrium alpha/(beta + gamma))",
                math.inf,
            )
        if d < 0:
            return BoundedClassVerdict(
                False,
                f"beta - gamma = {d:.6g} < 0: after an input reversal with x3 of the "
                "opposite sign, x3 can grow without bound",
                math.inf,
            )
        h_max = self.alpha / s
        return BoundedClassVerdict(
            True,
            f"alpha > 0, beta + gamma = {s:.6g} > 0 and beta - gamma = {d:.6g} >= 0: "
            f"|x3| stays within max(|x3(0)|, alpha/(beta + gamma) = {h_max:.6g} "
            f"{self.length_unit})",
            h_max,
        )

    @property
    def static_gain(self) -> float:
        """Linear static gain a3/a1 from u to x1 (length unit per volt)."""
        return self.a3 / self.a1

    def replace(self, **changes: Any) -> BoucWenParams:
        """A copy with some fields changed (re-validated)."""
        if any(k in changes for k in MODEL_FIELDS):
            changes.setdefault("physical", None)
        return replace(self, **changes)


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def require_bounded(params: BoucWenParams, allow_unbounded: bool = False) -> None:
    """Raise :class:`UnboundedModelError` unless the model is bounded or allowed.

    Parameters
    ----------
    params : BoucWenParams
    allow_unbounded : bool
        Accept a model outside the bounded class (for reproducing the paper's
        Section 4 set as printed).
    """
    verdict = params.bounded_class()
    if not verdict.bounded and not allow_unbounded:
        label = params.name or "the plant"
        raise UnboundedModelError(
            f"{label} is outside the bounded Bouc-Wen class: {verdict.reason}. "
            "Pass allow_unbounded=True (--allow-unbounded) to use it anyway."
        )


#: The paper's parameter sets by name (Section 5's identified stage, Section 4 as printed
#: and with its sign corrected); ``--plant`` and ``load_plant`` take these names, and
#: ``bwdesign presets`` lists them beside the bundled stage files.
PRESETS: dict[str, BoucWenParams] = {
    "paper_experiment": BoucWenParams(
        a1=159827.5,
        a2=713.8,
        a3=222665.02,
        alpha=0.4795,
        beta=0.3762,
        gamma=0.0378,
        name="paper_experiment",
    ),
    # Section 4 exactly as printed: beta + gamma < 0, so x3 diverges on any
    # rising input. Kept for reference; validation rejects it by default.
    "paper_simulation": BoucWenParams(
        a1=1.7168e8,
        a2=5743.0,
        a3=1.7808e9,
        alpha=4.6325,
        beta=-1.3567,
        gamma=0.4677,
        name="paper_simulation",
    ),
    # Our correction (not the paper's): beta = +1.3567 puts the set in the
    # bounded class, which Section 4's bounded simulation results imply.
    "paper_simulation_corrected": BoucWenParams(
        a1=1.7168e8,
        a2=5743.0,
        a3=1.7808e9,
        alpha=4.6325,
        beta=1.3567,
        gamma=0.4677,
        name="paper_simulation_corrected",
    ),
}

PRESET_NOTES: dict[str, str] = {
    "paper_experiment": "Zhao et al. 2024, Section 5: PI P-542.2 stage, identified parameters.",
    "paper_simulation": (
        "Zhao et al. 2024, Section 4 as printed (beta = -1.3567). Outside the bounded "
        "class: x3 diverges on any rising input."
    ),
    "paper_simulation_corrected": (
        "Zhao et al. 2024, Section 4 with beta = +1.3567. The sign correction is "
        "bwdesign's, not the paper's; it makes the set bounded."
    ),
}


def preset(name: str) -> BoucWenParams:
    """Return a bundled parameter set by name (see :data:`PRESETS`)."""
    from ..errors import ConfigError

    try:
        return PRESETS[name]
    except KeyError:
        raise ConfigError(
            f"unknown plant preset {name!r}; presets are {', '.join(sorted(PRESETS))}, "
            "or give a path to a .toml file"
        ) from None
