"""Identification: fit the Bouc-Wen stage model from a measured (t, u, y) record."""

from .data import DT_TOLERANCE, MIN_SAMPLES, IdentificationData, load_data
from .fit import identify
from .result import IdentificationResult, fit_percent

__all__ = [
    "identify",
    "IdentificationResult",
    "IdentificationData",
    "load_data",
    "fit_percent",
    "MIN_SAMPLES",
    "DT_TOLERANCE",
]
