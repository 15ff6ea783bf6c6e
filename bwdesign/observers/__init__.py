"""Observers: the base of the sampled filterpy-style observers, the PHSO, the ESO and the UKF
baseline; the structural form's observer (no certificate).
"""

from .dynamics import eso_rhs, eso_step, observer_iosystem, phso_rhs, phso_step
from .gains import check_gains, discrete_gains, error_matrix
from .sampled import DisturbanceHysteresisObserver, ExtendedStateObserver, HysteresisObserver
from .structural import StructuralObserver, structural_gains
from .ukf import UnscentedObserver, default_noise, max_hysteresis_slope

__all__ = [
    "check_gains",
    "error_matrix",
    "discrete_gains",
    "phso_step",
    "eso_step",
    "phso_rhs",
    "eso_rhs",
    "observer_iosystem",
    "HysteresisObserver",
    "ExtendedStateObserver",
    "DisturbanceHysteresisObserver",
    "UnscentedObserver",
    "StructuralObserver",
    "structural_gains",
    "default_noise",
    "max_hysteresis_slope",
]
