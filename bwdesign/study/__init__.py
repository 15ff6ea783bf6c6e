"""The computed study of a stage: everything the certified-gains report shows, computed once.

:func:`study` computes a :class:`Study` from a :class:`~bwdesign.model.config.StageConfig`;
the report renders it (:func:`bwdesign.report.certified.render`), ``certificate.json``
is its :meth:`Study.to_dict`, and ``bwdesign check``, the pytest plugin and
:mod:`bwdesign.testing` read their requirements from it.

The layer sits between the simulation and the report: it imports the model, the
observers, the control, the certificates and the simulation, never the report or
the plotting (figures are drawn by the report from the study's data).
"""

from .compute import study, versions
from .result import (
    CERTIFICATE_PARTS,
    DEFAULT_DECAY,
    PARTS,
    REPORT_PARTS,
    REPORT_SECTIONS,
    CornerTracking,
    Firmware,
    GainSetDynamics,
    InputRange,
    LoopStudy,
    PlantSummary,
    Recommendation,
    RobustLoop,
    RobustStudy,
    Study,
    StudySettings,
    SweepStudy,
    Synthesis,
    TierSynthesisStudy,
    Verdict,
)
from .tiers import TierSynthesis
from .tracking import TrackingRun

__all__ = [
    "study",
    "versions",
    "Study",
    "StudySettings",
    "PlantSummary",
    "InputRange",
    "Synthesis",
    "TierSynthesis",
    "TierSynthesisStudy",
    "GainSetDynamics",
    "LoopStudy",
    "TrackingRun",
    "CornerTracking",
    "SweepStudy",
    "RobustLoop",
    "RobustStudy",
    "Firmware",
    "Verdict",
    "Recommendation",
    "PARTS",
    "REPORT_PARTS",
    "CERTIFICATE_PARTS",
    "REPORT_SECTIONS",
    "DEFAULT_DECAY",
]
