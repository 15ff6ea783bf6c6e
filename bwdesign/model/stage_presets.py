"""The bundled stage configurations: package data in ``bwdesign/model/stages/*.toml``.

Each preset is a complete stage TOML file shipped inside the package (the
repository's ``configs/`` is a symlink to the same folder, so there is one copy).
:func:`bwdesign.load_config` and every ``--config`` take a preset's name (the
file's stem, e.g. ``paper_experiment``) as well as a path; a path that exists wins.
"""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import ConfigError

__all__ = ["STAGES_DIR", "stage_presets", "stage_preset_path", "resolve_config"]

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
