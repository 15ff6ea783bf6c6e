"""bwdesign: certified hysteresis observers and tracking controllers for Bouc-Wen actuators.

The public API is re-exported here name by name; everything else lives in
modules whose contents may change. The names are imported on first use:
``import bwdesign`` loads nothing heavy, so the command line starts at once
and handles a Ctrl-C from its first moment, and ``bwdesign.certify`` is the
function (as with an eager import) even after ``bwdesign.certify.lmi`` was
imported.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

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

if TYPE_CHECKING:  # the same names for type checkers (the package ships py.typed)
    from ._version import __version__
    from .certify.disturbance import LumpedCertificate, certify_disturbance
    from .certify.linear import ErrorDynamics, HysteresisBode, error_dynamics, hysteresis_bode
    from .certify.results import CertificateReport, Margin, SynthesisResult, TierCertificate
    from .certify.robust import RobustCertificate, certify_robust
    from .certify.robust_observer import (
        BoxSampling,
        RobustObserverCertificate,
        certify_robust_observer,
        certify_robust_observer_discrete,
    )
    from .certify.tiers import certify, certify_discrete
    from .codegen.export import CExport, export_c
    from .control.analysis import LoopAnalysis, analyze_loop, mismatch_sweep
    from .control.baseline_tuning import (
        BaselineAnalysis,
        analyze_baseline,
        make_baseline,
        tune_baseline,
    )
    from .control.baselines import (
        BaselineController,
        InverseBoucWenFeedforward,
        PrandtlFeedforward,
    )
    from .control.controllers import (
        DiscreteTrackingController,
        TrackingController,
        TuningWarning,
        make_controller,
    )
    from .control.loop import ClosedLoop, Start
    from .design.gains import synthesize
    from .design.robust import RobustDesign, RobustSearch, synthesize_robust
    from .design.robust_observer import RobustObserverSynthesis, synthesize_robust_observer
    from .design.tuning import DigitalTuning, digital_tuning
    from .identify import IdentificationResult, identify
    from .identify.prandtl import PrandtlFit, fit_prandtl_ishlinskii
    from .model.config import ControllerSettings, StageConfig, load_config, load_plant
    from .model.envelope import Envelope, derive_envelope, given_envelope
    from .model.params import PRESETS, BoucWenParams, BoundedClassVerdict, PhysicalParams, preset
    from .model.plant import hysteresis_increment, simulate_zoh, zoh_step
    from .model.prandtl import PrandtlIshlinskii
    from .model.references import Sine, Step, Triangle
    from .model.stage_presets import stage_presets
    from .model.uncertainty import DisturbanceBound, UncertaintyBox
    from .observers.sampled import (
        DisturbanceHysteresisObserver,
        ExtendedStateObserver,
        HysteresisObserver,
    )
    from .observers.spec import ObserverSpec
    from .observers.ukf import UnscentedObserver
    from .sim.batch import BatchResult, simulate_batch
    from .sim.closed_loop import simulate
    from .sim.continuous import ContinuousSolver, simulate_continuous
    from .sim.metrics import Metrics, steady_state_window, tracking_metrics
    from .sim.result import SimulationResult

#: Module -> the public names it provides, imported on first access.
_LAZY: dict[str, tuple[str, ...]] = {
    "._version": ("__version__",),
    ".certify.disturbance": ("LumpedCertificate", "certify_disturbance"),
    ".certify.linear": ("ErrorDynamics", "HysteresisBode", "error_dynamics", "hysteresis_bode"),
    ".certify.results": ("CertificateReport", "Margin", "SynthesisResult", "TierCertificate"),
    ".certify.robust": ("RobustCertificate", "certify_robust"),
    ".certify.robust_observer": (
        "BoxSampling",
        "RobustObserverCertificate",
        "certify_robust_observer",
        "certify_robust_observer_discrete",
    ),
    ".certify.tiers": ("certify", "certify_discrete"),
    ".codegen.export": ("CExport", "export_c"),
    ".control.analysis": ("LoopAnalysis", "analyze_loop", "mismatch_sweep"),
    ".control.baseline_tuning": (
        "BaselineAnalysis",
        "analyze_baseline",
        "make_baseline",
        "tune_baseline",
    ),
    ".control.baselines": (
        "BaselineController",
        "InverseBoucWenFeedforward",
        "PrandtlFeedforward",
    ),
    ".control.controllers": (
        "DiscreteTrackingController",
        "TrackingController",
        "TuningWarning",
        "make_controller",
    ),
    ".control.loop": ("ClosedLoop", "Start"),
    ".design.gains": ("synthesize",),
    ".design.robust": ("RobustDesign", "RobustSearch", "synthesize_robust"),
    ".design.robust_observer": ("RobustObserverSynthesis", "synthesize_robust_observer"),
    ".design.tuning": ("DigitalTuning", "digital_tuning"),
    ".identify": ("IdentificationResult", "identify"),
    ".identify.prandtl": ("PrandtlFit", "fit_prandtl_ishlinskii"),
    ".model.config": ("ControllerSettings", "StageConfig", "load_config", "load_plant"),
    ".model.envelope": ("Envelope", "derive_envelope", "given_envelope"),
    ".model.params": (
        "PRESETS",
        "BoucWenParams",
        "BoundedClassVerdict",
        "PhysicalParams",
        "preset",
    ),
    ".model.plant": ("hysteresis_increment", "simulate_zoh", "zoh_step"),
    ".model.prandtl": ("PrandtlIshlinskii",),
    ".model.references": ("Sine", "Step", "Triangle"),
    ".model.stage_presets": ("stage_presets",),
    ".model.uncertainty": ("UncertaintyBox", "DisturbanceBound"),
    ".observers.sampled": (
        "DisturbanceHysteresisObserver",
        "ExtendedStateObserver",
        "HysteresisObserver",
    ),
    ".observers.spec": ("ObserverSpec",),
    ".observers.ukf": ("UnscentedObserver",),
    ".sim.batch": ("BatchResult", "simulate_batch"),
    ".sim.closed_loop": ("simulate",),
    ".sim.continuous": ("ContinuousSolver", "simulate_continuous"),
    ".sim.metrics": ("Metrics", "steady_state_window", "tracking_metrics"),
    ".sim.result": ("SimulationResult",),
}

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
    "make_controller",
    "ClosedLoop",
    "Start",
    "ObserverSpec",
    "simulate",
    "simulate_batch",
    "BatchResult",
    "simulate_continuous",
    "ContinuousSolver",
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
    "RobustSearch",
    "certify_robust_observer",
    "certify_robust_observer_discrete",
    "synthesize_robust_observer",
    "RobustObserverCertificate",
    "RobustObserverSynthesis",
    "BoxSampling",
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
    "DisturbanceBound",
    "BaselineController",
    "InverseBoucWenFeedforward",
    "PrandtlFeedforward",
    "BaselineAnalysis",
    "analyze_baseline",
    "make_baseline",
    "tune_baseline",
    "PrandtlIshlinskii",
    "PrandtlFit",
    "fit_prandtl_ishlinskii",
]


class _Package(types.ModuleType):
    """The ``bwdesign`` module: each lazy name is a property of this class.

    A property of the class wins over the module's ``__dict__``, where the
    import system binds subpackages (``bwdesign.certify``, ``bwdesign.identify``),
    so the public function of the same name is what ``bwdesign.certify`` gives.
    """

    def __dir__(self) -> list[str]:
        return sorted(set(super().__dir__()) | set(__all__))


def _lazy(module: str, name: str) -> property:
    value: list[Any] = []  # the resolved (or assigned) object

    def get(self: types.ModuleType) -> Any:
        if not value:
            value.append(getattr(importlib.import_module(module, __name__), name))
        return value[0]

    def put(self: types.ModuleType, new: Any) -> None:
        if isinstance(new, types.ModuleType) and new.__name__ == f"{__name__}.{name}":
            self.__dict__[name] = new  # the import system binding a subpackage: shadowed
        else:  # an assignment (e.g. a test's monkeypatch)
            value[:] = [new]

    def forget(self: types.ModuleType) -> None:
        value.clear()

    return property(get, put, forget, f"{module[1:]}.{name} (imported on first use)")


for _module, _names in _LAZY.items():
    for _name in _names:
        setattr(_Package, _name, _lazy(_module, _name))
del _module, _names, _name
sys.modules[__name__].__class__ = _Package
