"""``bwdesign init STAGE.toml [--preset NAME]`` and ``bwdesign presets``.

``init`` writes a commented starter stage configuration: every section the
package reads, each key with its unit and default, the values of a bundled
stage configuration (``paper_experiment`` unless ``--preset`` names another).
Every section the preset has is active, its ``[observer]`` gains and
``[requirements]`` included, so the starter passes its own ``bwdesign check``;
a section the preset lacks ([synthesis], [uncertainty], ...) is written
commented out. The file loads with :func:`bwdesign.load_config`, and
``bwdesign report --config STAGE.toml`` and ``bwdesign check STAGE.toml`` run on it.
"""

from __future__ import annotations

import argparse
import json
import textwrap
import tomllib
from typing import Any

from .._version import __version__
from ..design.gains import default_pole_radius
from ..errors import ConfigError
from ..model.params import MODEL_FIELDS, BoucWenParams
from ..model.requirements import REQUIREMENT_KEYS, SETTING_KEYS
from ..model.stage_presets import (
    PresetEntry,
    preset_catalogue,
    stage_preset_path,
    stage_presets,
)
from ..output.files import prepare_file
from ..output.jsonenc import dump_json
from .args import EXIT_OK

__all__ = ["starter_config", "init_args", "run_init", "presets_args", "run_presets"]

DEFAULT_PRESET = "paper_experiment"
_WIDTH = 30  # column of the unit comments

#: Per section: (key, unit and meaning, default as TOML or None when required/none).
_PLANT_META = [
    ("name", "label used in reports", None),
    ("length_unit", "unit of the displacement x1 and the hysteresis state x3", '"um"'),
    ("input_unit", "unit of the input u", '"V"'),
]
_PLANT_MODEL = [
    ("a1", "1/s^2: stiffness over mass k/m, > 0", None),
    ("a2", "1/s: damping over mass b/m, >= 0", None),
    ("a3", "um/(V s^2): input gain k d/m, non-zero", None),
    ("alpha", "um/V: hysteresis gain alpha0 d, > 0", None),
]
_PLANT_PHYSICAL = [
    ("m", "kg: effective mass, > 0", None),
    ("b", "N s/m: damping, >= 0", None),
    ("k", "N/m: stiffness, > 0", None),
    ("d", "um/V: piezo coefficient, displacement per volt", None),
    ("alpha0", "1: hysteresis amplitude factor, alpha = alpha0 d", None),
]
_PLANT_SHAPE = [
    ("beta", "1/V: hysteresis shape (bounded class: beta + gamma > 0, beta >= gamma)", None),
    ("gamma", "1/V: hysteresis shape", None),
]
_SPEC: dict[str, list[tuple[str, str, str | None]]] = {
    "observer": [("gains", "[l1 (1/s), l2 (1/s^2), l3 (1/s)]: continuous-time gains", None)],
    "controller": [
        ("lambda1", "eq. (12) tracking-error constant, > 0", None),
        ("lambda2", "eq. (12) tracking-error constant, > 0", None),
        ("u_min", "V: amplifier lower limit (default: none)", None),
        ("u_max", "V: amplifier upper limit (default: none)", None),
    ],
    "sampling": [("dt", "s: sample time of the observer and controller, > 0", None)],
    "envelope": [
        ("from_reference", "derive the |u'| bound from [reference] (exact inverse)", None),
        ("margin", "1: factor >= 1 on the derived bound", "1.0"),
        ("udot_max", "V/s: the |u'| bound given directly, instead of from_reference", None),
    ],
    "reference": [
        ("kind", '"sine" | "triangle" | "step"', None),
        ("amplitude", "um: half the peak-to-peak travel (step: the step height)", None),
        ("offset", "um: mean position (step: the start)", "0.0"),
        ("frequency", "Hz: sine and triangle, > 0", None),
        ("phase", "rad: sine and triangle", "0.0"),
        (
            "corner_time",
            "s: triangle only, length of the parabolic corner blends, 0 = sharp",
            "0.0",
        ),
        ("t_step", "s: step only, time of the step", "0.0"),
        ("rise_time", "s: step only, length of the quintic rise, 0 = sharp", "0.0"),
    ],
    "synthesis": [
        ("decay", "1/s: decay rate asked of the synthesised gains", "100.0"),
        ("pole_radius", "rad/s: observer pole-disk radius", None),
    ],
    "uncertainty": [
        ("source", '"identified" (bwdesign identify writes it) or "specified"', None),
        ("level", "confidence level of the half-widths when they are intervals, e.g. 0.95", None),
    ]
    + [
        (k, "{ rel = 0.02 } (fraction of the nominal) or { abs = x }; unlisted = exact", None)
        for k in MODEL_FIELDS
    ],
    "sweep": [
        ("samples", "number of scenarios the report's Monte Carlo section runs, > 0", None),
        ("seed", "seed of the draw, >= 0 (default 0)", None),
        ("observers", '["phso", "eso", "phdo"]: the observers compared', None),
        (
            "tuning",
            '"config" ([observer] and [controller]) or "digital" (the digital tuning)',
            None,
        ),
        ("noise_std_um", "um: sensor noise std, >= 0 (default 0)", None),
        ("duration_s", "s: per scenario (default three reference periods, at least 1 s)", None),
        ("distribution", '"uniform" in the box, or "normal" (half-widths as 95 % intervals)', None),
    ],
    "baseline": [
        ("kind", '"pi" | "pid" | "pi-bwff" | "pi-piff": the PI/PID baseline checked', None),
        ("gains", "[kp, ki] ([kp, ki, kd, tf] for a pid); default the tuning rule", None),
        ("phase_margin", "deg: the tuning rule's phase margin (default 60)", None),
        ("delay", "true: tuned and analysed with a one-sample delay (default false)", None),
    ],
    # one source: the requirements schema (bwdesign check, bwdesign.testing)
    "requirements": [(k, meaning, None) for k, (_, meaning) in REQUIREMENT_KEYS.items()]
    + [(k, meaning, None) for k, (_, meaning) in SETTING_KEYS.items()],
}
_REFERENCE_KEYS = {
    "sine": {"amplitude", "offset", "frequency", "phase"},
    "triangle": {"amplitude", "offset", "frequency", "phase", "corner_time"},
    "step": {"amplitude", "offset", "t_step", "rise_time"},
}
_HEADINGS = {
    "plant": "the actuator model (required)",
    "observer": "gains the report certifies and `bwdesign check` checks (optional: without it, "
    "synthesis only)",
    "controller": "the tracking controller, paper eq. (12) (the report needs it)",
    "sampling": "the sample rate (the report needs it)",
    "envelope": "the input-rate envelope |u'| <= udot_max the certificates hold for",
    "reference": "the trajectory to track (the report needs it)",
    "synthesis": "what the report asks of the gain synthesis (optional)",
    "uncertainty": "parameter half-widths: the sweep's box, the requirements' corners (optional)",
    "sweep": "a Monte Carlo sweep over [uncertainty] in the report (optional; needs it)",
    "requirements": "what `bwdesign check` and your CI demand of the stage (optional)",
    "baseline": "a PI/PID baseline (no observer) the requirement baseline_stable checks (optional)",
}
_SECTION_ORDER = (
    "plant",
    "observer",
    "controller",
    "sampling",
    "reference",
    "envelope",
    "synthesis",
    "uncertainty",
    "sweep",
    "baseline",
    "requirements",
)


def _toml(value: Any) -> str:
    """A TOML literal for a value read from a TOML file."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    raise ConfigError(f"cannot write {value!r} as a starter value")


def _line(key: str, value: str, comment: str, *, active: bool) -> str:
    text = f"{'' if active else '# '}{key} = {value}"
    return f"{text:<{_WIDTH}} # {comment}"


def _entries(
    table: dict[str, Any], spec: list[tuple[str, str, str | None]], *, active: bool
) -> list[str]:
    """Lines for the keys of ``spec``: given ones set, defaults commented, the rest described."""
    out = []
    for key, comment, default in spec:
        if key in table:
            note = "" if default is None else f" (default {default})"
            out.append(_line(key, _toml(table[key]), comment + note, active=active))
        elif default is not None:
            out.append(_line(key, default, f"{comment} (default {default})", active=False))
        else:
            out.append(f"# {key}: {comment}")
    return out


def _plant(table: dict[str, Any]) -> list[str]:
    physical = any(k in table for k, _, _ in _PLANT_PHYSICAL)
    used, other = (_PLANT_PHYSICAL, _PLANT_MODEL) if physical else (_PLANT_MODEL, _PLANT_PHYSICAL)
    form = "physical form (paper eq. 1)" if physical else "model form (paper eq. 2)"
    alt = "model form a1, a2, a3, alpha" if physical else "physical form m, b, k, d, alpha0"
    lines = _entries(table, _PLANT_META, active=True)
    lines.append(f"# {form}; or the {alt} instead (not both):")
    lines += _entries(table, used, active=True)
    lines += _entries(table, _PLANT_SHAPE, active=True)
    lines += [f"#   {k}: {c}" for k, c, _ in other]
    return lines


def _reference(table: dict[str, Any]) -> list[str]:
    kind = table.get("kind", "sine")
    keys = _REFERENCE_KEYS[kind] | {"kind"}
    spec = [s for s in _SPEC["reference"] if s[0] in keys]
    lines = _entries(table, spec, active=True)
    others = [s for s in _SPEC["reference"] if s[0] not in keys]
    lines.append("# keys of the other kinds:")
    lines += [f"#   {k}: {c}" + ("" if d is None else f" (default {d})") for k, c, d in others]
    return lines


def _synthesis_default(data: dict[str, Any]) -> str:
    """The default pole radius (rad/s) for this stage, as text."""
    plant = BoucWenParams.from_dict(data["plant"])
    radius = default_pole_radius(plant, data.get("sampling", {}).get("dt"))
    return f"default min(10 sqrt(a1), 1/dt) = {radius:.6g} here"


def starter_config(preset: str | None = None) -> str:
    """The text of a commented starter stage configuration.

    Parameters
    ----------
    preset : str, optional
        Bundled stage configuration whose values fill the file (every section
        it has is active, so the file passes its own ``bwdesign check``).
        Default: ``paper_experiment``.

    Raises
    ------
    ConfigError
        ``preset`` is not a bundled stage configuration.
    """
    name = preset or DEFAULT_PRESET
    source = stage_preset_path(name)
    data = tomllib.loads(source.read_text(encoding="utf-8"))
    lines = [
        "# bwdesign stage configuration: one file per stage.",
        f"# Written by `bwdesign init` (bwdesign {__version__}) with the values of the bundled",
        f"# preset {name!r}:",
        *(f"#   {t}" for t in textwrap.wrap(stage_presets()[name], 84)),
        "# Replace them with your stage's, then: bwdesign report --config THIS.toml --out report",
        "#",
        "# Units: displacement um and input V (the plant's length_unit and input_unit),",
        "# time s. `# key = value` is an optional key at its default; `# key: ...` describes",
        "# a key that is not set; a section whose lines all start with `# ` is optional:",
        "# remove the `# ` to use it. Unknown sections and keys are errors.",
    ]
    for section in _SECTION_ORDER:
        table = data.get(section, {})
        active = section in data
        lines += ["", f"# [{section}]: {_HEADINGS[section]}"]
        if section == "plant":
            body = _plant(table)
        elif section == "reference":
            body = _reference(table)
        elif section == "synthesis":
            spec = [
                (k, c + (f" ({_synthesis_default(data)})" if k == "pole_radius" else ""), d)
                for k, c, d in _SPEC["synthesis"]
            ]
            body = _entries(table or {"decay": 100.0}, spec, active=True)
        else:
            body = _entries(table, _SPEC[section], active=True)
        header = f"[{section}]"
        if not active:
            header = "# " + header
            body = [b if b.startswith("#") else "# " + b for b in body]
        lines += [header, *body]
    return "\n".join(lines) + "\n"


def init_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", metavar="STAGE.toml", help="file to write (must not exist)")
    p.add_argument(
        "--preset",
        metavar="NAME",
        help=f"bundled stage configuration to start from (default {DEFAULT_PRESET}); see "
        "`bwdesign presets`",
    )


def run_init(args: argparse.Namespace) -> int:
    target = prepare_file(args.path, command="init", exclusive=True, what="STAGE.toml")
    target.write_text(starter_config(args.preset))
    print(f"wrote {target.path}; next: bwdesign report --config {target.path} --out report")
    return EXIT_OK


def presets_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print one JSON document")


def _use(entry: PresetEntry) -> str:
    """Where a preset's name is taken, and whether design commands refuse it."""
    where = "--plant, --config, init --preset" if entry.stage_file else "--plant only"
    return where if entry.bounded else f"{where}; unbounded: refused unless --allow-unbounded"


def run_presets(args: argparse.Namespace) -> int:
    presets = preset_catalogue()
    if args.json:
        doc = [
            {
                "name": e.name,
                "description": e.description,
                "stage_file": e.stage_file,
                "bounded": e.bounded,
                "use": _use(e),
            }
            for e in presets
        ]
        print(dump_json({"presets": doc}))
        return EXIT_OK
    width = max(len(e.name) for e in presets)
    for e in presets:
        print(f"{e.name:<{width}}  {e.description} [{_use(e)}]")
    return EXIT_OK
