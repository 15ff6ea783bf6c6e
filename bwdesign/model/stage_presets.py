"""The bundled stage configurations: package data in ``bwdesign/model/stages/*.toml``.

Each preset is a complete stage TOML file shipped inside the package (the
repository's ``configs/`` is a symlink to the same folder, so there is one copy).
:func:`bwdesign.load_config` and every ``--config`` take a preset's name (the
file's stem, e.g. ``paper_experiment``) as well as a path; a path that exists wins.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from ..errors import ConfigError
from .params import PRESET_NOTES, PRESETS, BoucWenParams

__all__ = [
    "STAGES_DIR",
    "PresetEntry",
    "preset_catalogue",
    "stage_presets",
    "stage_preset_path",
    "resolve_config",
    "unknown_plant_message",
]

#: Folder of the bundled stage configurations (inside the installed package).
STAGES_DIR = Path(__file__).with_name("stages")


def _describe(path: Path) -> str:
    """First sentence of the file's leading comment block (one line)."""
    lines = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("#").strip())
    text = " ".join(lines)
    # a sentence ends at ". " before a capital ("et al. 2024" does not end one)
    return re.split(r"(?<=\.)\s+(?=[A-Z])", text, maxsplit=1)[0]


def stage_presets() -> dict[str, str]:
    """The bundled stage configurations by name, each with a one-line description.

    Examples
    --------
    >>> "paper_experiment" in stage_presets()
    True
    """
    return {p.stem: _describe(p) for p in sorted(STAGES_DIR.glob("*.toml"))}


@dataclass(frozen=True)
class PresetEntry:
    """One name the command line takes as a preset.

    Attributes
    ----------
    name : str
    description : str
        One line.
    stage_file : bool
        True for a bundled stage configuration (``--plant``, ``--config``,
        ``init --preset``); False for a parameter set only (``--plant``, the
        Python :func:`bwdesign.preset`).
    bounded : bool
        Whether the parameters are in the bounded Bouc-Wen class; design and
        simulation commands refuse the others unless ``--allow-unbounded``
        (``params`` prints them with the verdict).
    """

    name: str
    description: str
    stage_file: bool
    bounded: bool


def preset_catalogue() -> list[PresetEntry]:
    """Every preset name, sorted: the one list ``bwdesign presets`` prints and errors quote.

    The bundled stage configurations (:func:`stage_presets`) and the parameter
    sets of :data:`bwdesign.PRESETS` that have no stage file (``paper_simulation``,
    the paper's Section 4 as printed, outside the bounded class).
    """
    stages = stage_presets()
    out = []
    for name in sorted(set(stages) | set(PRESETS)):
        if name in PRESETS:
            plant = PRESETS[name]
        else:  # a bundled file: its [plant] (the whole file is validated by load_config)
            text = stage_preset_path(name).read_text(encoding="utf-8")
            plant = BoucWenParams.from_dict(tomllib.loads(text)["plant"])
        out.append(
            PresetEntry(
                name=name,
                description=stages.get(name) or PRESET_NOTES.get(name, ""),
                stage_file=name in stages,
                bounded=plant.bounded_class().bounded,
            )
        )
    return out


def unknown_plant_message(name: str) -> str:
    """The error for a ``--plant`` that is neither a preset nor a file (lists every preset)."""
    names = ", ".join(e.name for e in preset_catalogue())
    return (
        f"unknown plant preset {name!r}; presets are {names} (bwdesign presets describes "
        "them), or give a path to a .toml file"
    )


def _names() -> str:
    return ", ".join(sorted(p.stem for p in STAGES_DIR.glob("*.toml")))


def stage_preset_path(name: str) -> Path:
    """The file of the bundled stage configuration ``name``.

    Raises
    ------
    ConfigError
        ``name`` is not a bundled stage configuration; the message lists them.
    """
    path = STAGES_DIR / f"{name}.toml"
    if "/" in name or "\\" in name or not path.is_file():
        raise ConfigError(f"unknown stage preset {name!r}; presets are {_names()}")
    return path


def resolve_config(name_or_path: str | Path) -> Path:
    """The file a ``--config`` argument names: an existing path, else a preset's file.

    A path that exists wins; a bare name (no folder, no suffix) that is not a
    preset is an error listing the presets. Anything else is returned as given,
    for the reader to report as a missing file.

    Raises
    ------
    ConfigError
        A bare name that is neither a file nor a preset.
    """
    path = Path(name_or_path)
    text = str(name_or_path)
    if path.exists() or path.suffix or "/" in text or "\\" in text:
        return path
    if (STAGES_DIR / f"{text}.toml").is_file():
        return STAGES_DIR / f"{text}.toml"
    raise ConfigError(
        f"{text!r} is neither a config file nor a stage preset; presets are {_names()} "
        "(bwdesign presets lists them)"
    )
