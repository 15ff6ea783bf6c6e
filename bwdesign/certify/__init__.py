"""Certificates: result types, the four tiers, the LMI programs (the only cvxpy, in :mod:`.lmi`)
and the linear analysis of the error dynamics (gain synthesis is in :mod:`bwdesign.design`).
"""

from .checks import continuous_equivalent, rho_interval, sector_interval
from .disturbance import (
    LumpedCertificate,
    certify_disturbance,
    synthesize_disturbance,
    verify_disturbance,
)
from .linear import (
    ErrorDynamics,
    HysteresisBode,
    error_dynamics,
    error_system,
    hinf_norm,
    hysteresis_bode,
    lipschitz_envelope,
)
from .results import TIERS, CertificateReport, Margin, SynthesisResult, TierCertificate
from .robust import RobustCertificate, certify_robust
from .robust_observer import (
    BoxSampling,
    RobustObserverCertificate,
    certify_robust_observer,
    certify_robust_observer_discrete,
)
from .tiers import certify, certify_discrete

__all__ = [
    "TIERS",
    "Margin",
    "TierCertificate",
    "CertificateReport",
    "SynthesisResult",
    "continuous_equivalent",
    "sector_interval",
    "rho_interval",
    "certify",
    "certify_discrete",
    "certify_robust",
    "RobustCertificate",
    "certify_robust_observer",
    "certify_robust_observer_discrete",
    "RobustObserverCertificate",
    "BoxSampling",
    "ErrorDynamics",
    "HysteresisBode",
    "error_system",
    "error_dynamics",
    "hinf_norm",
    "hysteresis_bode",
    "lipschitz_envelope",
    "LumpedCertificate",
    "certify_disturbance",
    "verify_disturbance",
    "synthesize_disturbance",
]
