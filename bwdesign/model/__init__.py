"""The stage model: parameters and presets, the exact ZOH plant, references, the operating envelope
and stage configuration (TOML).
"""

from .config import ControllerSettings, StageConfig, load_config, load_plant
from .envelope import Envelope, derive_envelope, given_envelope
from .params import (
    PRESETS,
    BoucWenParams,
    BoundedClassVerdict,
    PhysicalParams,
    preset,
    require_bounded,
)
from .plant import ZOHModel, discretize, hysteresis_increment, phi, rhs, simulate_zoh, zoh_step
from .references import Reference, Sine, Step, Triangle, reference_from_dict

__all__ = [
    "BoucWenParams",
    "PhysicalParams",
    "BoundedClassVerdict",
    "PRESETS",
    "preset",
    "require_bounded",
    "ZOHModel",
    "discretize",
    "phi",
    "rhs",
    "hysteresis_increment",
    "zoh_step",
    "simulate_zoh",
    "Reference",
    "Sine",
    "Triangle",
    "Step",
    "reference_from_dict",
    "Envelope",
    "derive_envelope",
    "given_envelope",
    "StageConfig",
    "ControllerSettings",
    "load_config",
    "load_plant",
]
