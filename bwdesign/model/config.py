"""Stage configuration files (TOML) and plant loading.

One file per stage; only ``[plant]`` is required::

    [plant]        name, then a1, a2, a3, alpha, beta, gamma
                   or the physical m, b, k, d, alpha0, beta, gamma;
                   optional length_unit (default "um") and input_unit (default "V");
                   or form = "structural" with m, c, k, alpha, beta, gamma, delta, nu
                   (bwdesign.model.structural; then only [sampling] may follow)
    [observer]     gains = [l1, l2, l3]   (continuous-time, 1/s, 1/s^2, 1/s)
    [controller]   lambda1, lambda2, optional u_min, u_max (input unit)
    [sampling]     dt (s)
    [envelope]     udot_max (input unit/s), or from_reference = true with optional margin >= 1
    [reference]    kind = "sine" | "triangle" | "step", amplitude, offset, frequency, ...
    [synthesis]    decay (1/s) and pole_radius (rad/s) asked of the gain synthesis in reports
    [uncertainty]  per-parameter half-widths (bwdesign.model.uncertainty)

Unknown sections and keys are errors that name the allowed ones. Numbers are in
the plant's units: length_unit for x1, x3 and the reference, input_unit for u
and input_unit/s for rates; nothing is converted.
"""

from __future__ import annotations

import hashlib
import math
import os
import stat
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import BWDesignError, ConfigError, InputError, ParameterError
from ..validate import (
    DECAY,
    DT,
    GAIN,
    LAMBDA,
    NONNEGATIVE,
    POLE_RADIUS,
    POSITIVE,
    SEED,
    SIGNAL,
    UDOT_MAX,
    Range,
    below_nyquist,
    integer,
    real,
)
from .envelope import Envelope, derive_envelope, given_envelope
from .params import PRESETS, BoucWenParams, preset
from .plant import check_sample_time
from .references import Reference, reference_from_dict
from .requirements import parse_requirements
from .stage_presets import resolve_config, stage_presets, unknown_plant_message
from .structural import StructuralParams
from .uncertainty import DisturbanceBound, UncertaintyBox

__all__ = [
    "StageConfig",
    "ControllerSettings",
    "load_config",
    "load_plant",
    "parse_toml",
    "BASELINE_KINDS",
]

#: The baseline controllers (:mod:`bwdesign.control.baselines`), by their names in
#: ``[baseline] kind`` and ``bwdesign simulate --controller``.
BASELINE_KINDS = ("pi", "pid", "pi-bwff", "pi-piff")

_SECTIONS = {
    "plant": None,
    "observer": {"gains"},
    "controller": {"lambda1", "lambda2", "u_min", "u_max"},
    "sampling": {"dt"},
    "envelope": {"udot_max", "from_reference", "margin"},
    "reference": None,  # checked per kind
    "synthesis": {"decay", "pole_radius"},
    "sweep": {
        "samples",
        "seed",
        "observers",
        "tuning",
        "noise_std_um",
        "duration_s",
        "distribution",
    },
    "requirements": None,  # checked by model.requirements
    "uncertainty": None,  # checked by UncertaintyBox.from_dict
    "baseline": {"kind", "gains", "phase_margin", "delay"},
}


@dataclass(frozen=True, kw_only=True)
class ControllerSettings:
    """Eq. (12) constants (1/s) and optional amplifier limits (the plant's input unit)."""

    lambda1: float
    lambda2: float
    u_min: float | None = None
    u_max: float | None = None

    def input_limits(self) -> tuple[float, float] | None:
        """``(u_min, u_max)`` for a controller (``-inf``/``inf`` for a missing side), or
        ``None`` without limits: the one place a stage's amplifier limits are built."""
        if self.u_min is None and self.u_max is None:
            return None
        lo = -math.inf if self.u_min is None else float(self.u_min)
        return (lo, math.inf if self.u_max is None else float(self.u_max))

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
    plant : BoucWenParams or StructuralParams
        The piezo form (default) or ``form = "structural"``.
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
    requirements : dict or None
        The ``[requirements]`` a user's CI checks (:mod:`bwdesign.model.requirements`).
    sweep : dict or None
        The ``[sweep]`` the report runs over ``[uncertainty]`` (off when absent).
    baseline : dict or None
        ``[baseline]``: a baseline controller the stage's checks hold to
        (``kind``; ``gains`` or the tuning rule's ``phase_margin``; ``delay``).
    uncertainty : UncertaintyBox or None
        The ``[uncertainty]`` section (None when absent or when it lists no parameter).
    disturbance : DisturbanceBound or None
        ``[uncertainty.disturbance]``: what the model does not explain, as a bounded,
        slowly varying input-equivalent disturbance (None when absent).
    source : str
        Path of the file.
    sha256 : str
        Hash of the file's bytes, for reproducibility blocks.
    """

    plant: BoucWenParams | StructuralParams
    gains: tuple[float, float, float] | None = None
    controller: ControllerSettings | None = None
    dt: float | None = None
    reference: Reference | None = None
    envelope_spec: dict[str, Any] | None = None
    synthesis: dict[str, float] | None = None
    requirements: dict[str, Any] | None = None
    uncertainty: UncertaintyBox | None = None
    disturbance: DisturbanceBound | None = None
    sweep: dict[str, Any] | None = None
    baseline: dict[str, Any] | None = None
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


def _num(value: Any, where: str, *, positive: bool = False, within: Range | None = None) -> float:
    """A TOML number through :func:`bwdesign.validate.real` (``ConfigError``).

    ``positive`` without ``within``: any finite number > 0 (:data:`POSITIVE`).
    """
    if within is None and positive:
        within = POSITIVE
    return real(value, where, within=within, error=ConfigError)


#: Supported range of the envelope margin (a factor >= 1).
MARGIN = Range(1.0, 1e6)
#: Number of scenarios of a ``[sweep]`` (its upper limit is the sweep's own, by memory).
SAMPLES = Range(1, math.inf)


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


def _sweep(table: Any) -> dict[str, Any] | None:
    """``[sweep]``: a small Monte Carlo sweep over ``[uncertainty]`` in the report."""
    t = _check_keys(table, "sweep", _SECTIONS["sweep"])
    if not t:  # an empty section asks for nothing, as for [requirements] and [uncertainty]
        return None
    if "samples" not in t:
        raise ConfigError("[sweep]: missing key samples (number of scenarios, > 0)")
    out: dict[str, Any] = {
        "seed": 0,
        "observers": ("phso", "eso"),
        "tuning": "config",
        "noise_std_um": 0.0,
        "distribution": "uniform",
    }
    for key, within in (("samples", SAMPLES), ("seed", SEED)):
        if key in t:
            out[key] = integer(t[key], f"[sweep] {key}", within=within, error=ConfigError)
    choices = {"tuning": ("config", "digital"), "distribution": ("uniform", "normal")}
    for key, allowed in choices.items():
        if key in t:
            if t[key] not in allowed:
                raise ConfigError(f"[sweep] {key} must be one of {allowed}, got {t[key]!r}")
            out[key] = t[key]
    if "observers" in t:
        obs = t["observers"]
        allowed = ("phso", "eso", "phdo", *BASELINE_KINDS)
        if not isinstance(obs, list) or not obs or any(o not in allowed for o in obs):
            raise ConfigError(
                f"[sweep] observers must be a list of {', '.join(map(repr, allowed))} (the "
                f"last {len(BASELINE_KINDS)}: baselines, no observer), got {obs!r}"
            )
        twice = sorted({o for o in obs if obs.count(o) > 1})
        if twice:
            raise ConfigError(
                f"[sweep] observers must each be given once, got {', '.join(twice)} more than "
                "once (every scenario would count twice)"
            )
        out["observers"] = tuple(obs)
    for key, within in (("noise_std_um", NONNEGATIVE), ("duration_s", POSITIVE)):
        if key in t:
            out[key] = _num(t[key], f"[sweep] {key}", within=within)
    return out


def _baseline(table: Any) -> dict[str, Any] | None:
    """``[baseline]``: ``kind``, ``gains`` (2 for a PI, 4 for a PID) or ``phase_margin``."""
    t = _check_keys(table, "baseline", _SECTIONS["baseline"])
    if not t:  # an empty section asks for nothing, as for [sweep]
        return None
    kind = t.get("kind")
    if kind not in BASELINE_KINDS:
        raise ConfigError(f"[baseline] kind must be one of {BASELINE_KINDS}, got {kind!r}")
    out: dict[str, Any] = {"kind": kind, "gains": None, "phase_margin": 60.0, "delay": False}
    if "gains" in t and "phase_margin" in t:
        raise ConfigError("[baseline]: give gains or phase_margin (the tuning rule), not both")
    if "gains" in t:
        g, n = t["gains"], 4 if kind == "pid" else 2
        if not isinstance(g, list) or len(g) != n:
            want = "[kp, ki, kd, tf]" if n == 4 else "[kp, ki]"
            raise ConfigError(f"[baseline] gains of a {kind} must be {want}, got {g!r}")
        out["gains"] = tuple(
            _num(v, f"[baseline] gains[{i}]", within=GAIN) for i, v in enumerate(g)
        )
    if "phase_margin" in t:
        out["phase_margin"] = _num(
            t["phase_margin"], "[baseline] phase_margin (deg)", positive=True
        )
    if "delay" in t:
        if not isinstance(t["delay"], bool):
            raise ConfigError(f"[baseline] delay must be true or false, got {t['delay']!r}")
        out["delay"] = t["delay"]
    return out


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
        plant = plant_from_dict(data["plant"])
    except ParameterError as err:
        raise ConfigError(str(err)) from None
    if isinstance(plant, StructuralParams):
        return _structural_config(plant, data, source=source, sha256=sha256)

    gains = None
    if "observer" in data:
        obs = _check_keys(data["observer"], "observer", _SECTIONS["observer"])
        if "gains" not in obs:
            raise ConfigError("[observer]: missing key gains = [l1, l2, l3]")
        g = obs["gains"]
        if not isinstance(g, list) or len(g) != 3:
            shown = repr(g) if len(repr(g)) <= 60 else f"{type(g).__name__} of length {len(g)}"
            raise ConfigError(f"[observer]: gains must be a list of 3 numbers, got {shown}")
        gains = tuple(_num(v, f"[observer] gains[{i}]", within=GAIN) for i, v in enumerate(g))

    controller = None
    if "controller" in data:
        c = _check_keys(data["controller"], "controller", _SECTIONS["controller"])
        for k in ("lambda1", "lambda2"):
            if k not in c:
                raise ConfigError(f"[controller]: missing key {k}")
        lim = {
            k: (_num(c[k], f"[controller] {k}", within=SIGNAL) if k in c else None)
            for k in ("u_min", "u_max")
        }
        if lim["u_min"] is not None and lim["u_max"] is not None and lim["u_min"] >= lim["u_max"]:
            raise ConfigError("[controller]: u_min must be below u_max")
        controller = ControllerSettings(
            lambda1=_num(c["lambda1"], "[controller] lambda1", positive=True, within=LAMBDA),
            lambda2=_num(c["lambda2"], "[controller] lambda2", positive=True, within=LAMBDA),
            **lim,
        )

    dt = None
    if "sampling" in data:
        s = _check_keys(data["sampling"], "sampling", _SECTIONS["sampling"])
        if "dt" not in s:
            raise ConfigError("[sampling]: missing key dt (s)")
        dt = _num(s["dt"], "[sampling] dt", positive=True, within=DT)
        try:
            dt = check_sample_time(plant, dt)
        except InputError as err:
            raise ConfigError(f"[sampling] {err}") from None

    reference = None
    if "reference" in data:
        reference = reference_from_dict(data["reference"])
        if dt is not None:
            below_nyquist(reference, dt, what="[reference]", error=ConfigError)

    env = None
    if "envelope" in data:
        env = dict(_check_keys(data["envelope"], "envelope", _SECTIONS["envelope"]))
        if "udot_max" in env:
            if "from_reference" in env or "margin" in env:
                raise ConfigError(
                    "[envelope]: give either udot_max or from_reference (with margin), not both"
                )
            env["udot_max"] = _num(
                env["udot_max"],
                "[envelope] udot_max (input unit/s)",
                positive=True,
                within=UDOT_MAX,
            )
        elif env.get("from_reference") is True:
            if reference is None:
                raise ConfigError("[envelope]: from_reference = true needs a [reference] section")
            if "margin" in env:
                env["margin"] = _num(env["margin"], "[envelope] margin", within=MARGIN)
        else:
            raise ConfigError(
                "[envelope]: give udot_max (input unit/s, a positive number) or "
                "from_reference = true"
            )

    synthesis = None
    if "synthesis" in data:
        syn = _check_keys(data["synthesis"], "synthesis", _SECTIONS["synthesis"])
        ranges = {"decay": DECAY, "pole_radius": POLE_RADIUS}
        synthesis = {
            k: _num(syn[k], f"[synthesis] {k}", positive=k == "pole_radius", within=ranges[k])
            for k in syn
        }

    sweep = _sweep(data["sweep"]) if "sweep" in data else None

    uncertainty, disturbance = _uncertainty(data.get("uncertainty"))
    return StageConfig(
        plant=plant,
        gains=gains,
        controller=controller,
        dt=dt,
        reference=reference,
        envelope_spec=env,
        synthesis=synthesis,
        requirements=(parse_requirements(data["requirements"]) or None)
        if "requirements" in data
        else None,
        uncertainty=uncertainty,
        disturbance=disturbance,
        sweep=sweep,
        baseline=_baseline(data["baseline"]) if "baseline" in data else None,
        source=source,
        sha256=sha256,
    )


__all__ += ["plant_from_dict", "require_form", "FORMS"]

#: The model forms a ``[plant]`` table names with ``form`` (the first is the default).
FORMS = ("piezo", "structural")
#: The commands that take a structural stage; every other one refuses it (:func:`require_form`).
STRUCTURAL_COMMANDS = ("params", "validate", "identify --form structural")


def plant_from_dict(table: Any) -> BoucWenParams | StructuralParams:
    """A ``[plant]`` table in either form: ``form = "piezo"`` (the default) or ``"structural"``.

    Raises
    ------
    ParameterError
        An unknown form, and every check of the form's parameters.
    """
    form = table.get("form", FORMS[0]) if isinstance(table, dict) else FORMS[0]
    if form not in FORMS:
        raise ParameterError(
            f"[plant] form must be one of {', '.join(repr(f) for f in FORMS)}, got {form!r}",
            field="form",
        )
    if form == "structural":
        return StructuralParams.from_dict(table)
    return BoucWenParams.from_dict({k: v for k, v in table.items() if k != "form"})


def _structural_config(
    plant: StructuralParams, data: dict[str, Any], *, source: str, sha256: str
) -> StageConfig:
    """A structural stage: ``[plant]`` and an optional ``[sampling]`` dt, nothing else."""
    other = sorted(set(data) - {"plant", "sampling"})
    if other:
        raise ConfigError(
            f'[plant] form = "structural" takes only [sampling] beside it; the structural '
            f"Bouc-Wen form has no observer, controller or certificate sections yet, got "
            f"{', '.join('[' + o + ']' for o in other)}"
        )
    dt = None
    if "sampling" in data:
        s = _check_keys(data["sampling"], "sampling", _SECTIONS["sampling"])
        if "dt" not in s:
            raise ConfigError("[sampling]: missing key dt (s)")
        dt = _num(s["dt"], "[sampling] dt", positive=True, within=DT)
    return StageConfig(plant=plant, dt=dt, source=source, sha256=sha256)


def require_form(config: StageConfig, forms: tuple[str, ...], source: str = "") -> StageConfig:
    """``config`` if its plant's form is in ``forms``, else the one refusal every command gives.

    Raises
    ------
    ConfigError
        Names the form and the commands that take it.
    """
    form = getattr(config.plant, "form", FORMS[0])
    if form in forms:
        return config
    where = f"{source}: " if source else ""
    if form == "structural":
        raise ConfigError(
            f'{where}[plant] form = "structural" (the structural Bouc-Wen form) is not '
            f"supported by this command; it is supported by bwdesign "
            f"{', '.join(STRUCTURAL_COMMANDS)} "
            '(README.md, section "The structural Bouc-Wen form")'
        )
    raise ConfigError(f"{where}[plant] form = {form!r} is not supported by this command")


def _uncertainty(table: Any) -> tuple[UncertaintyBox | None, DisturbanceBound | None]:
    """``[uncertainty]`` (None when absent or when it lists no parameter) and its
    ``[uncertainty.disturbance]`` (None when absent)."""
    if table is None:
        return None, None
    box = UncertaintyBox.from_dict(table)
    dist = DisturbanceBound.from_dict(table["disturbance"]) if "disturbance" in table else None
    return (box if box.widths else None), dist


#: Largest stage file read (bytes): a stage file is a few hundred bytes.
MAX_CONFIG_BYTES = 1 << 20


def parse_toml(raw: bytes, where: str) -> dict[str, Any]:
    """TOML bytes to a table: UTF-8 with an optional byte-order mark (as spreadsheet
    programs and some editors write), nesting no deeper than Python's parser goes.

    Raises
    ------
    ConfigError
        Not UTF-8, malformed TOML, or values nested too deeply to read (a
        ``RecursionError`` inside :mod:`tomllib`).
    """
    try:
        return tomllib.loads(raw.decode("utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(f"{where}: malformed TOML: {err}") from None
    except RecursionError:
        raise ConfigError(
            f"{where}: malformed TOML: arrays or tables nested too deeply to read"
        ) from None


def load_config(path: str | Path, *, forms: tuple[str, ...] = FORMS[:1]) -> StageConfig:
    """Read and validate a stage configuration file.

    ``forms``: the model forms the caller takes (:data:`FORMS`); a stage of another
    form is refused with one :class:`~bwdesign.errors.ConfigError` naming it
    (:func:`require_form`). The default takes the piezo form only, so every command
    written for it refuses a structural stage.

    ``path`` may also name a bundled stage configuration (``paper_experiment``,
    see :func:`bwdesign.stage_presets`); a path that exists wins.

    A UTF-8 byte-order mark at the start of the file is accepted.

    Raises
    ------
    ConfigError
        Missing file, malformed TOML, unknown sections or keys, wrong types.
    """
    if not str(path).strip():
        raise ConfigError("an empty path names no config file")
    path = resolve_config(path)
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            raise ConfigError(f"config file {str(path)!r} is not a regular file")
        if st.st_size > MAX_CONFIG_BYTES:
            raise ConfigError(
                f"config file {str(path)!r} is {st.st_size} bytes; a stage file holds at most "
                f"{MAX_CONFIG_BYTES} bytes"
            )
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"config file {str(path)!r} does not exist") from None
    except OSError as err:
        raise ConfigError(f"cannot read config file {str(path)!r}: {err.strerror}") from None
    data = parse_toml(raw, str(path))
    try:
        config = parse_config(data, source=str(path), sha256=hashlib.sha256(raw).hexdigest())
        return require_form(config, forms)
    except BWDesignError as err:
        text = str(err)  # name the file once, whether or not the message already does
        raise ConfigError(text if text.startswith(f"{path}: ") else f"{path}: {text}") from None


def load_plant(
    name_or_path: str | Path, *, forms: tuple[str, ...] = FORMS[:1]
) -> BoucWenParams | StructuralParams:
    """A plant by preset name (``paper_experiment``, ...) or from a TOML file.

    A string that is a preset name gives the preset; anything else is read as a
    configuration file (or a bundled stage configuration by name, see
    :func:`bwdesign.stage_presets`) and its ``[plant]`` section returned (the
    whole file is validated). ``forms`` as for :func:`load_config`.

    Examples
    --------
    >>> load_plant("paper_experiment").a1
    159827.5
    """
    if isinstance(name_or_path, str) and name_or_path in PRESETS:
        return preset(name_or_path)
    p = Path(name_or_path)
    if not str(name_or_path).strip() or (
        p.suffix.lower() != ".toml" and not p.exists() and str(p) not in stage_presets()
    ):
        raise ConfigError(unknown_plant_message(str(name_or_path)))
    return load_config(p, forms=forms).plant
