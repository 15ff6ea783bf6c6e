"""Stage configuration files (TOML) and plant loading.

One file per stage; only ``[plant]`` is required::

    [plant]        name, then a1, a2, a3, alpha, beta, gamma
                   or the physical m, b, k, d, alpha0, beta, gamma
    [observer]     gains = [l1, l2, l3]   (continuous-time, 1/s, 1/s^2, 1/s)
    [controller]   lambda1, lambda2, optional u_min, u_max (V)
    [sampling]     dt (s)
    [envelope]     udot_max (V/s), or from_reference = true with optional margin >= 1
    [reference]    kind = "sine" | "triangle" | "step", amplitude, offset, frequency, ...
    [synthesis]    decay (1/s) and pole_radius (rad/s) asked of the gain synthesis in reports
    [uncertainty]  per-parameter half-widths (bwdesign.model.uncertainty)

Unknown sections and keys are errors that name the allowed ones.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import BWDesignError, ConfigError, ParameterError
from .envelope import Envelope, derive_envelope, given_envelope
from .params import PRESETS, BoucWenParams, preset
from .references import Reference, reference_from_dict
from .uncertainty import UncertaintyBox

__all__ = ["StageConfig", "ControllerSettings", "load_config", "load_plant"]

_SECTIONS = {
    "plant": None,
    "observer": {"gains"},
    "controller": {"lambda1", "lambda2", "u_min", "u_max"},
    "sampling": {"dt"},
    "envelope": {"udot_max", "from_reference", "margin"},
    "reference": None,  # checked per kind
    "synthesis": {"decay", "pole_radius"},
    "uncertainty": None,  # checked by UncertaintyBox.from_dict
}


@dataclass(frozen=True, kw_only=True)
class ControllerSettings:
    """Eq. (12) constants and optional amplifier limits (V)."""

    lambda1: float
    lambda2: float
    u_min: float | None = None
    u_max: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "lambda1": self.lambda1,
            "lambda2": self.lambda2,
            "u_min": self.u_min,
            "u_max": self.u_max,
        }


@dataclass(frozen=True, kw_only=True)
class StageConfig:
    """A parsed stage configuration.

    Attributes
    ----------
    plant : BoucWenParams
    gains : tuple of 3 floats or None
        Continuous-time observer gains (l1, l2, l3).
    controller : ControllerSettings or None
    dt : float or None
        Sample time (s).
    reference : Reference or None
    envelope_spec : dict or None
        The ``[envelope]`` table as given; see :meth:`envelope`.
    synthesis : dict or None
        ``decay`` (1/s) and ``pole_radius`` (rad/s) for the report's gain synthesis.
    uncertainty : UncertaintyBox or None
        The ``[uncertainty]`` section (None when absent).
    source : str
        Path of the file.
    sha256 : str
        Hash of the file's bytes, for reproducibility blocks.
    """

    plant: BoucWenParams
    gains: tuple[float, float, float] | None = None
    controller: ControllerSettings | None = None
    dt: float | None = None
    reference: Reference | None = None
    envelope_spec: dict[str, Any] | None = None
    synthesis: dict[str, float] | None = None
    uncertainty: UncertaintyBox | None = None
    source: str = ""
    sha256: str = ""

    def envelope(self, *, allow_unbounded: bool = False) -> Envelope | None:
        """The operating envelope: given, or derived from ``[reference]``."""
        spec = self.envelope_spec
        if spec is None:
            return None
        if "udot_max" in spec:
            return given_envelope(spec["udot_max"])
        return derive_envelope(
            self.plant,
            self.reference,
            margin=spec.get("margin", 1.0),
            allow_unbounded=allow_unbounded,
        )


def _num(value: Any, where: str, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(f"{where} must be finite, got {value}")
    if positive and value <= 0:
        raise ConfigError(f"{where} must be a positive number, got {value:g}")
    return value


def _check_keys(table: Any, section: str, allowed: set[str]) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise ConfigError(f"[{section}] must be a table, got {type(table).__name__}")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ConfigError(
            f"[{section}]: unknown key(s) {', '.join(unknown)}; allowed keys are "
            f"{', '.join(sorted(allowed))}"
        )
    return table


def parse_config(data: dict[str, Any], *, source: str = "", sha256: str = "") -> StageConfig:
    """Validate a parsed TOML document and build a :class:`StageConfig`."""
    unknown = sorted(set(data) - set(_SECTIONS))
    if unknown:
        raise ConfigError(
            f"{source or 'config'}: unknown section(s) {', '.join('[' + u + ']' for u in unknown)};"
            f" allowed sections are {', '.join('[' + s + ']' for s in _SECTIONS)}"
        )
    if "plant" not in data:
        raise ConfigError(f"{source or 'config'}: missing required section [plant]")
    try:
        plant = BoucWenParams.from_dict(data["plant"])
    except ParameterError as err:
        raise ConfigError(str(err)) from None

    gains = None
    if "observer" in data:
        obs = _check_keys(data["observer"], "observer", _SECTIONS["observer"])
        if "gains" not in obs:
            raise ConfigError("[observer]: missing key gains = [l1, l2, l3]")
        g = obs["gains"]
        if not isinstance(g, list) or len(g) != 3:
            raise ConfigError(f"[observer]: gains must be a list of 3 numbers, got {g!r}")
        gains = tuple(_num(v, f"[observer] gains[{i}]") for i, v in enumerate(g))

    controller = None
    if "controller" in data:
        c = _check_keys(data["controller"], "controller", _SECTIONS["controller"])
        for k in ("lambda1", "lambda2"):
            if k not in c:
                raise ConfigError(f"[controller]: missing key {k}")
        lim = {k: (_num(c[k], f"[controller] {k}") if k in c else None) for k in ("u_min", "u_max")}
        if lim["u_min"] is not None and lim["u_max"] is not None and lim["u_min"] >= lim["u_max"]:
            raise ConfigError("[controller]: u_min must be below u_max")
        controller = ControllerSettings(
            lambda1=_num(c["lambda1"], "[controller] lambda1", positive=True),
            lambda2=_num(c["lambda2"], "[controller] lambda2", positive=True),
            **lim,
        )

    dt = None
    if "sampling" in data:
        s = _check_keys(data["sampling"], "sampling", _SECTIONS["sampling"])
        if "dt" not in s:
            raise ConfigError("[sampling]: missing key dt (s)")
        dt = _num(s["dt"], "[sampling] dt", positive=True)

    reference = None
    if "reference" in data:
        reference = reference_from_dict(data["reference"])

    env = None
    if "envelope" in data:
        env = dict(_check_keys(data["envelope"], "envelope", _SECTIONS["envelope"]))
        if "udot_max" in env:
            if "from_reference" in env or "margin" in env:
                raise ConfigError(
                    "[envelope]: give either udot_max or from_reference (with margin), not both"
                )
            env["udot_max"] = _num(env["udot_max"], "[envelope] udot_max (V/s)", positive=True)
        elif env.get("from_reference") is True:
            if reference is None:
                raise ConfigError("[envelope]: from_reference = true needs a [reference] section")
            if "margin" in env:
                env["margin"] = _num(env["margin"], "[envelope] margin")
                if env["margin"] < 1:
                    raise ConfigError(f"[envelope] margin must be >= 1, got {env['margin']:g}")
        else:
            raise ConfigError(
                "[envelope]: give udot_max (V/s, a positive number) or from_reference = true"
            )

    synthesis = None
    if "synthesis" in data:
        syn = _check_keys(data["synthesis"], "synthesis", _SECTIONS["synthesis"])
        synthesis = {k: _num(syn[k], f"[synthesis] {k}", positive=k == "pole_radius") for k in syn}
        if synthesis.get("decay", 0.0) < 0:
            raise ConfigError(f"[synthesis] decay must be >= 0 (1/s), got {synthesis['decay']:g}")

    uncertainty = None
    if "uncertainty" in data:
        uncertainty = UncertaintyBox.from_dict(data["uncertainty"])

    return StageConfig(
        plant=plant,
        gains=gains,
        controller=controller,
        dt=dt,
        reference=reference,
        envelope_spec=env,
        synthesis=synthesis,
        uncertainty=uncertainty,
        source=source,
        sha256=sha256,
    )


def load_config(path: str | Path) -> StageConfig:
    """Read and validate a stage configuration file.

    Raises
    ------
    ConfigError
        Missing file, malformed TOML, unknown sections or keys, wrong types.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"config file {str(path)!r} does not exist") from None
    except OSError as err:
        raise ConfigError(f"cannot read config file {str(path)!r}: {err.strerror}") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: malformed TOML: {err}") from None
    try:
        return parse_config(data, source=str(path), sha256=hashlib.sha256(raw).hexdigest())
    except BWDesignError as err:
        raise ConfigError(f"{path}: {err}") from None


def load_plant(name_or_path: str | Path) -> BoucWenParams:
    """A plant by preset name (``paper_experiment``, ...) or from a TOML file.

    A string that is a preset name gives the preset; anything else is read as a
    configuration file and its ``[plant]`` section returned (the whole file is
    validated).

    Examples
    --------
    >>> load_plant("paper_experiment").a1
    159827.5
    """
    if isinstance(name_or_path, str) and name_or_path in PRESETS:
        return preset(name_or_path)
    p = Path(name_or_path)
    if p.suffix.lower() != ".toml" and not p.exists():
        return preset(str(name_or_path))  # raises the "unknown preset" error
    return load_config(p).plant
