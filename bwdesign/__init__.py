"""bwdesign: certified hysteresis observers and tracking controllers for Bouc-Wen actuators.

The public API is re-exported here name by name; everything else lives in
modules whose contents may change.
"""

from ._version import __version__
from .certify.disturbance import LumpedCertificate, certify_disturbance
from .certify.linear import ErrorDynamics, HysteresisBode, error_dynamics, hysteresis_bode
from .certify.results import CertificateReport, Margin, SynthesisResult, TierCertificate
from .certify.robust import RobustCertificate, certify_robust
from .certify.robust_observer import (
    RobustObserverCertificate,
    RobustObserverSynthesis,
    certify_robust_observer,
    synthesize_robust_observer,
)
from .certify.synthesis import synthesize
from .certify.tiers import certify, certify_discrete
from .codegen.export import CExport, export_c
from .control.analysis import LoopAnalysis, analyze_loop, mismatch_sweep
from .control.controllers import DiscreteTrackingController, TrackingController, TuningWarning
from .control.tuning import DigitalTuning, digital_tuning
from .errors import (
    BWDesignError,
    ConfigError,
    GainError,
    InputError,
    MissingExtraError,
    NotCertifiedError,
    OutputError,
    ParameterError,
    SolverError,
    UnboundedModelError,
)
from .identify import IdentificationResult, identify
from .model.config import ControllerSettings, StageConfig, load_config, load_plant
from .model.envelope import Envelope, derive_envelope, given_envelope
from .model.params import PRESETS, BoucWenParams, BoundedClassVerdict, PhysicalParams, preset
from .model.plant import hysteresis_increment, simulate_zoh, zoh_step
from .model.references import Sine, Step, Triangle
from .model.stage_presets import stage_presets
from .model.uncertainty import UncertaintyBox
from .observers.sampled import (
    DisturbanceHysteresisObserver,
    ExtendedStateObserver,
    HysteresisObserver,
)
from .observers.ukf import UnscentedObserver
from .sim.closed_loop import simulate
from .sim.continuous import simulate_continuous
from .sim.metrics import Metrics, steady_state_window, tracking_metrics
from .sim.result import SimulationResult
from .sim.robust_design import RobustDesign, synthesize_robust
from .sim.start import start_on_reference

__all__ = [
    "__version__",
    "BoucWenParams",
    "PhysicalParams",
    "BoundedClassVerdict",
    "PRESETS",
    "preset",
    "load_plant",
    "load_config",
    "stage_presets",
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
    "DisturbanceHysteresisObserver",
    "ExtendedStateObserver",
    "UnscentedObserver",
    "hysteresis_increment",
    "zoh_step",
    "simulate_zoh",
    "TrackingController",
    "DiscreteTrackingController",
    "TuningWarning",
    "simulate",
    "start_on_reference",
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
    "MissingExtraError",
    "NotCertifiedError",
    "export_c",
    "CExport",
    "certify",
    "certify_discrete",
    "certify_disturbance",
    "LumpedCertificate",
    "certify_robust",
    "RobustCertificate",
    "synthesize_robust",
    "RobustDesign",
    "certify_robust_observer",
    "synthesize_robust_observer",
    "RobustObserverCertificate",
    "RobustObserverSynthesis",
    "synthesize",
    "CertificateReport",
    "TierCertificate",
    "Margin",
    "SynthesisResult",
    "error_dynamics",
    "hysteresis_bode",
    "ErrorDynamics",
    "HysteresisBode",
    "OutputError",
    "identify",
    "IdentificationResult",
    "UncertaintyBox",
]
