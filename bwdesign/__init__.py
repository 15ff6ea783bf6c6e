"""bwdesign: certified hysteresis observers and tracking controllers for Bouc-Wen actuators.

The public API is re-exported here name by name; everything else lives in
modules whose contents may change.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bwdesign")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

from .certify import (
    CertificateReport,
    Margin,
    SynthesisResult,
    TierCertificate,
    certify,
    certify_discrete,
    synthesize,
)
from .config import ControllerSettings, StageConfig, load_config, load_plant
from .envelope import Envelope, derive_envelope, given_envelope
from .errors import (
    BWDesignError,
    ConfigError,
    GainError,
    InputError,
    ParameterError,
    SolverError,
    UnboundedModelError,
)
from .linear import ErrorDynamics, HysteresisBode, error_dynamics, hysteresis_bode
from .loop import DigitalTuning, LoopAnalysis, analyze_loop, digital_tuning, mismatch_sweep
from .metrics import Metrics, steady_state_window, tracking_metrics
from .observers import ExtendedStateObserver, HysteresisObserver
from .params import PRESETS, BoucWenParams, BoundedClassVerdict, PhysicalParams, preset
from .plant import hysteresis_increment, simulate_zoh, zoh_step
from .references import Sine, Step, Triangle
from .simulate import SimulationResult, simulate, simulate_continuous
from .tracking import DiscreteTrackingController, TrackingController, TuningWarning
from .ukf import UnscentedObserver

__all__ = [
    "__version__",
    "BoucWenParams",
    "PhysicalParams",
    "BoundedClassVerdict",
    "PRESETS",
    "preset",
    "load_plant",
    "load_config",
    "StageConfig",
    "ControllerSettings",
    "Envelope",
    "derive_envelope",
    "given_envelope",
    "Sine",
    "Triangle",
    "Step",
    "Metrics",
    "tracking_metrics",
    "steady_state_window",
    "HysteresisObserver",
    "ExtendedStateObserver",
    "UnscentedObserver",
    "hysteresis_increment",
    "zoh_step",
    "simulate_zoh",
    "TrackingController",
    "DiscreteTrackingController",
    "TuningWarning",
    "simulate",
    "simulate_continuous",
    "SimulationResult",
    "analyze_loop",
    "mismatch_sweep",
    "digital_tuning",
    "LoopAnalysis",
    "DigitalTuning",
    "BWDesignError",
    "ConfigError",
    "ParameterError",
    "UnboundedModelError",
    "GainError",
    "InputError",
    "SolverError",
    "certify",
    "certify_discrete",
    "synthesize",
    "CertificateReport",
    "TierCertificate",
    "Margin",
    "SynthesisResult",
    "error_dynamics",
    "hysteresis_bode",
    "ErrorDynamics",
    "HysteresisBode",
]
