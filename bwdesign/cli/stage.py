"""``--plant NAME_OR_TOML``: a preset, or a stage file whose sections give option defaults.

With a stage file, ``certify``, ``synthesize`` and ``simulate`` take every
option the command line leaves out from the file's sections (``[observer]``
gains, ``[sampling]`` dt, ``[envelope]`` udot_max, ``[controller]`` lambda1,
lambda2, u_min, u_max, ``[reference]``, ``[synthesis]`` decay and
pole_radius); an option given on the command line wins. What came from the
file is printed (text: a ``from FILE:`` line; JSON: ``defaults_from_file``).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..model.config import StageConfig, load_config, load_plant
from ..model.params import PRESETS, BoucWenParams

__all__ = ["Stage", "load_stage", "resolved_copy"]


@dataclass
class Stage:
    """The plant of ``--plant`` and, for a file, its configuration.

    Attributes
    ----------
    params : BoucWenParams
    config : StageConfig or None
        None for a preset name.
    used : dict
        Option name -> the section it was taken from (filled by :meth:`default`).
    """

    params: BoucWenParams
    config: StageConfig | None = None
    used: dict[str, str] = field(default_factory=dict)

    def default(self, args: argparse.Namespace, option: str, section: str, value: Any) -> Any:
        """``args.<option>`` if given, else ``value`` from the file (recorded in ``used``)."""
        given = getattr(args, option)
        if given is not None or value is None:
            return given
        self.used["--" + option.replace("_", "-")] = section
        return value

    def to_dict(self) -> dict[str, Any] | None:
        if self.config is None:
            return None
        return {"source": self.config.source, "options": dict(self.used)}

    def note(self) -> str | None:
        """The ``from FILE: ...`` line, or None when nothing came from the file."""
        if not self.used:
            return None
        opts = ", ".join(f"{k} ({v})" for k, v in self.used.items())
        return f"from {self.config.source}: {opts}"


def load_stage(name_or_path: str) -> Stage:
    """A preset by name, or a stage file (validated as a whole)."""
    if name_or_path in PRESETS or (
        Path(name_or_path).suffix.lower() != ".toml" and not Path(name_or_path).exists()
    ):
        return Stage(params=load_plant(name_or_path))
    config = load_config(name_or_path)
    return Stage(params=config.plant, config=config)


def resolved_copy(args: argparse.Namespace) -> argparse.Namespace:
    """A copy of a command's options for resolving the file's defaults into: the namespace
    argparse returned is never changed (a command may be run twice with it)."""
    return argparse.Namespace(**vars(args))
