"""The structural Bouc-Wen form: hysteresis in the restoring force, driven by the output velocity.

The model of MR dampers, base isolators and the hysteretic benchmark of Noël and
Schoukens (2016) (docs/design.md, section "The structural form")::

    m y'' + c y' + k y + z = u
    z' = alpha y' - beta (gamma |y'| |z|^(nu-1) z + delta y' |z|^nu)

``y`` is the measured displacement (``length_unit``, default m), ``u`` the applied
force (``input_unit``, default N) and ``z`` the hysteretic restoring force (input
unit). Units: m in N s^2/m, c in N s/m, k and alpha in N/m, beta in
1/(m N^(nu-1)), gamma, delta and nu dimensionless (with the stage's units in place
of m and N; nothing is converted).

Along a monotone stroke the z equation is an ODE in y (it is rate independent)::

    dz/dy = alpha - beta (gamma sigma + delta s) |z|^(nu-1) z,   sigma = sgn y', s = sgn z

Whether z stays bounded (:meth:`StructuralParams.bounded_class`) follows from the
signs of the four quadrant coefficients ``beta (gamma sigma + delta s)``:

* ``alpha > 0``, ``beta (gamma + delta) > 0`` and ``beta (gamma - delta) >= 0``
  (Ikhouane and Rodellar's class for every input): ``|z| <= max(|z(0)|, z_max)``
  with ``z_max = (alpha / (beta (gamma + delta)))^(1/nu)``.
* otherwise, at ``nu = 1``: z is linear in itself on every branch, so it cannot
  escape in a finite stroke; ``|z| <= (|z(0)| + alpha V) exp(c_max V)`` with ``V``
  the total variation of y and ``c_max = |beta| (|gamma| + |delta|)``: bounded on
  every record of bounded stroke (the benchmark's parameters are of this kind:
  ``beta (gamma + delta) = -300``).
* otherwise, at ``nu > 1``: z reaches infinity within a finite monotone stroke;
  refused (:class:`~bwdesign.errors.UnboundedModelError`) unless allowed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..errors import ParameterError, UnboundedModelError
from ..validate import Range, real

__all__ = [
    "StructuralParams",
    "StructuralVerdict",
    "STRUCTURAL_FIELDS",
    "STRUCTURAL_RANGES",
    "require_bounded_structural",
    "BENCHMARK",
]

STRUCTURAL_FIELDS = ("m", "c", "k", "alpha", "beta", "gamma", "delta", "nu")
_META = ("name", "length_unit", "input_unit")

#: Supported range of each parameter (wide enough for any structure, narrow enough
#: that nothing inside the simulator overflows).
STRUCTURAL_RANGES: dict[str, Range] = {
    "m": Range(1e-12, 1e12),
    "c": Range(0.0, 1e12),
    "k": Range(0.0, 1e12),
    "alpha": Range(0.0, 1e12, lo_open=True),
    "beta": Range(-1e12, 1e12),
    "gamma": Range(-1e12, 1e12),
    "delta": Range(-1e12, 1e12),
    "nu": Range(1.0, 20.0),
}


@dataclass(frozen=True)
class StructuralVerdict:
    """Whether z stays bounded (module docstring).

    Attributes
    ----------
    bounded : bool
        True in the class bounded for every input.
    finite_escape : bool
        True when z can reach infinity within a finite stroke (nu > 1 outside the class).
    reason : str
        One sentence naming the condition that holds or fails.
    z_max : float
        The bound on |z| in the class (input unit), ``inf`` otherwise.
    growth : float
        ``c_max``, the exponential growth rate of |z| per unit stroke outside the
        class at nu = 1 (1/length unit); 0 in the class.
    """

    bounded: bool
    finite_escape: bool
    reason: str
    z_max: float
    growth: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "bounded": self.bounded,
            "finite_escape": self.finite_escape,
            "reason": self.reason,
            "z_max": self.z_max,
            "growth_per_stroke": self.growth,
        }


@dataclass(frozen=True, kw_only=True)
class StructuralParams:
    """Parameters of the structural Bouc-Wen form (module docstring).

    Raises
    ------
    ParameterError
        A value is non-numeric, non-finite or out of range (``nu < 1`` included);
        ``err.field`` names it.

    Examples
    --------
    >>> p = BENCHMARK
    >>> p.bounded_class().finite_escape
    False
    >>> round(p.beta * p.gamma, 6), round(p.beta * p.delta, 6)
    (800.0, -1100.0)
    """

    m: float
    c: float
    k: float
    alpha: float
    beta: float
    gamma: float
    delta: float
    nu: float = 1.0
    name: str = ""
    length_unit: str = "m"
    input_unit: str = "N"

    form = "structural"

    def __post_init__(self) -> None:
        owner = f"[plant] {self.name!r} (structural)" if self.name else "[plant] (structural)"
        for f in STRUCTURAL_FIELDS:
            value = real(
                getattr(self, f), f"{owner}: {f}", within=STRUCTURAL_RANGES[f], error=ParameterError
            )
            object.__setattr__(self, f, value)
        for f in _META:
            if not isinstance(getattr(self, f), str):
                raise ParameterError(f"{owner}: {f} must be a string", field=f)

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, owner: str = "[plant]") -> StructuralParams:
        """Build from a ``[plant]`` table with ``form = "structural"``.

        Raises
        ------
        ParameterError
            Unknown keys or a missing parameter (nu defaults to 1).
        """
        if not isinstance(data, dict):
            raise ParameterError(f"{owner} must be a table, got {type(data).__name__}")
        allowed = {"form", *STRUCTURAL_FIELDS, *_META}
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise ParameterError(
                f'{owner} (form = "structural"): unknown key(s) {", ".join(unknown)}; allowed '
                f"keys are {', '.join(sorted(allowed))}",
                field=unknown[0],
            )
        missing = [k for k in STRUCTURAL_FIELDS[:-1] if k not in data]
        if missing:
            raise ParameterError(
                f'{owner} (form = "structural"): missing field(s) {", ".join(missing)}',
                field=missing[0],
            )
        return cls(**{k: v for k, v in data.items() if k != "form"})

    # -- views -------------------------------------------------------------
    @property
    def units(self) -> dict[str, str]:
        """The unit of every parameter in the stage's length and input units."""
        lu, iu = self.length_unit, self.input_unit
        beta = f"1/{lu}" if self.nu == 1 else f"1/({lu} {iu}^{self.nu - 1:g})"
        return {
            "m": f"{iu} s^2/{lu}",
            "c": f"{iu} s/{lu}",
            "k": f"{iu}/{lu}",
            "alpha": f"{iu}/{lu}",
            "beta": beta,
            "gamma": "-",
            "delta": "-",
            "nu": "-",
        }

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for JSON."""
        out: dict[str, Any] = {"form": self.form, "name": self.name}
        out.update({f: getattr(self, f) for f in STRUCTURAL_FIELDS})
        out["length_unit"] = self.length_unit
        out["input_unit"] = self.input_unit
        return out

    def to_toml(self) -> str:
        """A ``[plant]`` table that :func:`bwdesign.load_config` reads back exactly."""
        lines = ["[plant]", 'form = "structural"', f"name = {_toml_str(self.name)}"]
        lines += [f"{f} = {getattr(self, f)!r}" for f in STRUCTURAL_FIELDS]
        lines.append(f"length_unit = {_toml_str(self.length_unit)}")
        lines.append(f"input_unit = {_toml_str(self.input_unit)}")
        return "\n".join(lines) + "\n"

    def bounded_class(self) -> StructuralVerdict:
        """Classify the parameters by whether z stays bounded (module docstring)."""
        up = self.beta * (self.gamma + self.delta)
        down = self.beta * (self.gamma - self.delta)
        if up > 0 and down >= 0:
            z_max = (self.alpha / up) ** (1.0 / self.nu)
            return StructuralVerdict(
                True,
                False,
                f"beta (gamma + delta) = {up:.6g} > 0 and beta (gamma - delta) = {down:.6g} >= 0: "
                f"|z| stays within max(|z(0)|, {z_max:.6g} {self.input_unit}) for every input",
                z_max,
                0.0,
            )
        which = (
            f"beta (gamma + delta) = {up:.6g} <= 0"
            if up <= 0
            else f"beta (gamma - delta) = {down:.6g} < 0"
        )
        if self.nu == 1.0:
            growth = abs(self.beta) * (abs(self.gamma) + abs(self.delta))
            return StructuralVerdict(
                False,
                False,
                f"{which}: z is not bounded for every input, but at nu = 1 it cannot escape in "
                f"a finite stroke: |z| <= (|z(0)| + alpha V) exp({growth:.6g} V) for a total "
                f"displacement variation V ({self.length_unit})",
                math.inf,
                growth,
            )
        return StructuralVerdict(
            False,
            True,
            f"{which} with nu = {self.nu:g} > 1: z reaches infinity within a finite monotone "
            "stroke",
            math.inf,
            math.inf,
        )

    def replace(self, **changes: Any) -> StructuralParams:
        """A copy with some fields changed (re-validated)."""
        data = self.to_dict()
        data.update(changes)
        return StructuralParams.from_dict(data)


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def require_bounded_structural(params: StructuralParams, allow_unbounded: bool = False) -> None:
    """Raise :class:`UnboundedModelError` when z can escape in a finite stroke (unless allowed)."""
    verdict = params.bounded_class()
    if verdict.finite_escape and not allow_unbounded:
        label = params.name or "the plant"
        raise UnboundedModelError(
            f"{label} (structural Bouc-Wen form): {verdict.reason}. Pass allow_unbounded=True "
            "(--allow-unbounded) to use it anyway."
        )


#: The hysteretic benchmark's published parameters (Noël and Schoukens, 2016), SI units.
BENCHMARK = StructuralParams(
    m=2.0,
    c=10.0,
    k=5e4,
    alpha=5e4,
    beta=1e3,
    gamma=0.8,
    delta=-1.1,
    nu=1.0,
    name="boucwen_benchmark",
)
