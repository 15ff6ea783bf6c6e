"""The computed study of a stage: one frozen, typed result behind the report and the checks.

:class:`Study` holds every number the certified-gains report shows, in typed parts
(:data:`PARTS`), computed by :func:`bwdesign.study.study`. A part that was not asked
for is ``None`` and absent from :attr:`Study.parts`; :meth:`Study.get` says so. A
part that does not apply to the stage (no ``[sweep]``, no ``[uncertainty]``, no
``[observer]`` gains) is computed as ``None`` and listed in :attr:`Study.parts`.

:meth:`Study.to_dict` is ``certificate.json``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from ..certify.linear import ErrorDynamics, HysteresisBode
from ..certify.results import CertificateReport, SynthesisResult
from ..certify.robust import RobustCertificate
from ..control.analysis import LoopAnalysis
from ..design.tuning import DigitalTuning
from ..errors import InputError
from ..model.config import StageConfig
from ..model.envelope import Envelope
from ..model.params import BoucWenParams
from ..model.uncertainty import DisturbanceBound
from ..sim.batch import BatchResult
from ..sim.falsify import Falsification
from ..sim.sweep import SweepSpec
from .baselines import BaselineComparison, ConfiguredBaseline
from .tiers import TierSynthesis
from .tracking import TrackingRun

__all__ = [
    "Study",
    "StudySettings",
    "PlantSummary",
    "InputRange",
    "Synthesis",
    "TierSynthesisStudy",
    "GainSetDynamics",
    "LoopStudy",
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

#: Decay rate (1/s) requested from synthesis when the config has no [synthesis] decay.
DEFAULT_DECAY = 100.0

#: Every part of a study, in the order they are computed (the report's progress order).
PARTS = (
    "plant",
    "envelope",
    "input",
    "configured",
    "synthesis",
    "tuning",
    "tracking",
    "verdict",
    "tier_synthesis",
    "error_dynamics",
    "loop",
    "sweep",
    "robust",
    "firmware",
    "recommendation",
    "versions",
    "corner_tracking",
    "baselines",
    "baseline",
)
#: The parts the certified-gains report shows (all but the requirements' corner tracking
#: and the ``[baseline]`` check's analysis).
REPORT_PARTS = frozenset(PARTS) - {"corner_tracking", "baseline"}
#: The parts behind ``certificate.json`` without the report's own sections.
CERTIFICATE_PARTS = frozenset(("plant", "envelope", "input", "configured", "synthesis", "firmware"))
#: Entries of ``certificate.json`` the report's own sections add (each from its part).
REPORT_SECTIONS = ("tier_synthesis", "sweep", "robust", "baselines")


@dataclass(frozen=True)
class StudySettings:
    """What a study asks beyond the stage file (the checks' settings; defaults as the report).

    Parameters
    ----------
    decay : float
        Decay rate (1/s) the configured gains' certificate requires (``configured``).
    observer : {"phso", "eso", "phdo"}
        Observer of the requirements' tracking runs (``corner_tracking``).
    noise_std : float
        Their sensor noise std (length unit), seeded.
    duration : float, optional
        Their simulated time (s); default three reference periods, at least 1 s.
    start : {"reference", "rest"}
        Start on the reference (as the report's runs) or from zero state and input.
    mismatch : mapping, optional
        Relative parameter errors of the one simulated plant (``{"a1": 0.02}``); default
        the nominal plant and every ``[uncertainty]`` corner.
    """

    decay: float = 0.0
    observer: str = "phso"
    noise_std: float = 0.0
    duration: float | None = None
    start: str = "reference"
    mismatch: Mapping[str, float] | None = None

    def __post_init__(self) -> None:
        # the numbers are checked where they meet the simulation (as every run's are)
        if self.mismatch is not None:
            object.__setattr__(self, "mismatch", dict(self.mismatch))

    @classmethod
    def from_requirements(cls, requirements: Mapping[str, Any] | None) -> StudySettings:
        """The tracking settings of a ``[requirements]`` section (its defaults when absent)."""
        req = requirements or {}
        return cls(
            observer=req.get("observer", "phso"),
            noise_std=req.get("noise_std_um", 0.0),
            duration=req.get("duration_s"),
            start=req.get("start", "reference"),
        )


@dataclass(frozen=True)
class PlantSummary:
    """The plant table: parameters, derived linear quantities, bounded-class verdict."""

    params: BoucWenParams
    natural_frequency_hz: float
    damping_ratio: float
    static_gain: float
    static_gain_unit: str
    bounded: bool
    bounded_reason: str
    note: str | None = None


@dataclass(frozen=True)
class InputRange:
    """Input limits, the feedforward input the reference needs (exact inverse), and the fit.

    ``within_limits`` is None when either is unknown.
    """

    limits: tuple[float, float] | None
    feedforward: tuple[float, float] | None
    within_limits: bool | None

    def to_dict(self) -> dict[str, Any]:
        return {
            "limits": None if self.limits is None else list(self.limits),
            "feedforward_range": None if self.feedforward is None else list(self.feedforward),
            "within_limits": self.within_limits,
        }


#: ``certificate.json``'s ``synthesis`` entry: these keys of :meth:`SynthesisResult.to_dict`.
_SYNTHESIS_KEYS = (
    "feasible",
    "tier",
    "gains",
    "discrete_gains",
    "decay",
    "pole_radius",
    "binding",
    "reason",
    "max_decay",
    "max_udot",
    "solver",
    "status",
)


@dataclass(frozen=True)
class Synthesis:
    """The stage's gain synthesis: what was asked (``[synthesis]``) and the result."""

    decay: float
    pole_radius: float | None
    result: SynthesisResult

    def to_dict(self) -> dict[str, Any]:
        doc = self.result.to_dict()
        return {k: doc[k] for k in _SYNTHESIS_KEYS}


@dataclass(frozen=True)
class TierSynthesisStudy:
    """Synthesis per tier: the largest envelope gains synthesised for each tier reach."""

    udot_max: float
    decay: float
    search_rtol: float
    rows: tuple[TierSynthesis, ...]

    def row(self, tier: str) -> TierSynthesis:
        return next(r for r in self.rows if r.tier == tier)

    def to_dict(self) -> dict[str, Any]:
        return {
            "udot_max": self.udot_max,
            "decay": self.decay,
            "search_rtol": self.search_rtol,
            "tiers": [r.to_dict() for r in self.rows],
        }


@dataclass(frozen=True)
class GainSetDynamics:
    """The observer error dynamics of one gain set (``configured`` or ``synthesised``)."""

    label: str
    gains: tuple[float, ...]
    dynamics: ErrorDynamics
    bode: HysteresisBode


@dataclass(frozen=True)
class LoopStudy:
    """Eq. (12) with the ``[controller]`` constants and the loop's gains, continuous and at dt.

    ``gains``: the ``[observer]`` gains, else the synthesised ones.
    """

    lambda1: float
    lambda2: float
    gains: tuple[float, ...]
    continuous: LoopAnalysis
    sampled: LoopAnalysis


@dataclass(frozen=True)
class CornerTracking:
    """The ``[controller]`` law tracking ``[reference]`` on the plants the requirements name.

    The nominal plant and every ``[uncertainty]`` corner (or the one plant
    ``settings.mismatch`` gives), simulated together by :func:`bwdesign.simulate_batch`
    on :meth:`bwdesign.ClosedLoop.from_config`.
    """

    settings: StudySettings
    duration: float
    plants: int
    result: BatchResult


@dataclass(frozen=True)
class SweepStudy:
    """The report's Monte Carlo sweep over ``[uncertainty]`` (``[sweep]``)."""

    spec: SweepSpec
    tuning: str
    bounds: dict[str, tuple[float, float]]
    samples: int
    seed: int
    distribution: str
    table: Mapping[str, Any]
    summary: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        return {
            "samples": self.samples,
            "seed": self.seed,
            "distribution": self.distribution,
            "bounds": self.bounds,
            "summary": self.summary,
        }


@dataclass(frozen=True)
class RobustLoop:
    """One observer's robust certificate beside the worst error simulated at the corners.

    The simulated columns are steady-state max ``|error|`` over the batch's window;
    ``conservatism`` = certified / simulated tracking error (None when not certified).
    """

    observer: str
    gains: tuple[float, ...]
    certificate: RobustCertificate
    envelope: float
    simulated_input_rate_max: float
    simulated_worst_maxe: float
    simulated_worst_estimation_maxe: tuple[float, float, float]
    simulated_window: tuple[float, float]
    samples: int
    all_corners_stable: bool
    conservatism: float | None
    #: the falsifier's search (corners, interior, seeded optimiser): the found worst case
    found: Falsification | None = None

    def to_dict(self) -> dict[str, Any]:
        doc = {f.name: getattr(self, f.name) for f in fields(self)}
        for k in ("gains", "simulated_worst_estimation_maxe", "simulated_window"):
            doc[k] = list(doc[k])
        doc["certificate"] = self.certificate.to_dict()
        doc["found"] = self.found.to_dict() if self.found is not None else None
        # the certified upper bound, the found lower bound and their ratio, side by side
        doc["tracking_bound"] = self.certificate.tracking_bound
        doc["found_worst_maxe"] = self.simulated_worst_maxe
        doc["found_ratio"] = self.conservatism
        return doc


@dataclass(frozen=True)
class RobustStudy:
    """Robust certificates over ``[uncertainty]`` (``loops``; none without a box) and for
    the nominal plant (``nominal``) of the digital tuning's loop (PHSO, PHDO)."""

    udot_max: float
    bounds: dict[str, tuple[float, float]]
    loops: tuple[RobustLoop, ...]
    #: the stage's input disturbance the certificates assumed (None: none)
    disturbance: DisturbanceBound | None = None
    #: the same certificate for the nominal plant alone (a box of zero width)
    nominal: tuple[RobustLoop, ...] = ()

    def loop(self, observer: str) -> RobustLoop | None:
        return next((lp for lp in self.loops if lp.observer == observer), None)

    def to_dict(self) -> dict[str, Any]:
        doc: dict[str, Any] = {"observers": {lp.observer: lp.to_dict() for lp in self.loops}}
        doc["nominal"] = {lp.observer: lp.to_dict() for lp in self.nominal}
        if self.disturbance is not None:
            doc["disturbance"] = self.disturbance.to_dict()
        return doc


#: The observer update the firmware gains are for.
FIRMWARE_FORM = "x_post = x_prior + K (z - x_prior[0]); see bwdesign.observers"


@dataclass(frozen=True)
class Firmware:
    """Discrete observer gains at dt for the firmware (full precision).

    ``pole_matched``: :func:`bwdesign.observers.gains.discrete_gains` of the
    ``[observer]`` gains, the check of ``configured_K``.
    """

    dt: float
    configured_K: tuple[float, ...] | None
    synthesized_K: tuple[float, ...] | None
    pole_matched: tuple[float, ...] | None

    def to_dict(self) -> dict[str, Any]:
        doc: dict[str, Any] = {"dt": self.dt, "form": FIRMWARE_FORM}
        if self.configured_K is not None:
            doc["configured_K"] = list(self.configured_K)
        if self.synthesized_K is not None:
            doc["synthesized_K"] = list(self.synthesized_K)
        return doc


@dataclass(frozen=True)
class Verdict:
    """The sentence at the top of the report and the flag behind ``bwdesign report``'s exit code."""

    ok: bool
    text: str


@dataclass(frozen=True)
class Recommendation:
    """The loop the summary recommends: the digital tuning or eq. (12), always with the PHSO.

    ``law`` is None (and ``run`` too) when no PHSO run stays bounded.
    """

    law: str | None
    run: TrackingRun | None


@dataclass(frozen=True)
class Study:
    """Everything the certified-gains report shows, computed once from a stage.

    Attributes
    ----------
    config : StageConfig
    allow_unbounded : bool
    settings : StudySettings
    parts : frozenset of str
        The parts computed (see :data:`PARTS`); the others are None.
    plant : PlantSummary
    envelope : Envelope
        The input-rate envelope the certificates use (``[envelope]``).
    input : InputRange
    configured : CertificateReport or None
        The ``[observer]`` gains certified at the envelope (None without gains).
    synthesis : Synthesis
    tuning : DigitalTuning
    tracking : tuple of TrackingRun
        {eq. 12, digital tuning} x {PHSO, ESO, PHDO}, each with its reproducing command.
    verdict : Verdict
    tier_synthesis : TierSynthesisStudy
    error_dynamics : tuple of GainSetDynamics
    loop : LoopStudy
    sweep : SweepStudy or None
        Without ``[sweep]``: None.
    robust : RobustStudy or None
        Without a determined ``[uncertainty]`` box: None.
    firmware : Firmware
    recommendation : Recommendation
    versions : dict
        Python and the libraries the numbers came from.
    corner_tracking : CornerTracking
        The requirements' tracking runs (not in the report).
    baselines : BaselineComparison
        The baseline controllers beside the observer-based loops, nominal and at the
        worst corner (:mod:`bwdesign.study.baselines`).
    baseline : ConfiguredBaseline or None
        The ``[baseline]`` controller's nominal analysis (None without the section; not
        in the report).
    cache_key : str or None
        The key of this study in the study cache (:mod:`bwdesign.study.cache`); None
        when computed without one.
    cached : frozenset of str
        The parts read from the cache rather than computed (empty without one).
    """

    config: StageConfig
    allow_unbounded: bool
    settings: StudySettings
    parts: frozenset[str]
    plant: PlantSummary | None = None
    envelope: Envelope | None = None
    input: InputRange | None = None
    configured: CertificateReport | None = None
    synthesis: Synthesis | None = None
    tuning: DigitalTuning | None = None
    tracking: tuple[TrackingRun, ...] | None = None
    verdict: Verdict | None = None
    tier_synthesis: TierSynthesisStudy | None = None
    error_dynamics: tuple[GainSetDynamics, ...] | None = None
    loop: LoopStudy | None = None
    sweep: SweepStudy | None = None
    robust: RobustStudy | None = None
    firmware: Firmware | None = None
    recommendation: Recommendation | None = None
    versions: Mapping[str, str] | None = None
    corner_tracking: CornerTracking | None = None
    baselines: BaselineComparison | None = None
    baseline: ConfiguredBaseline | None = None
    cache_key: str | None = field(default=None, compare=False)
    cached: frozenset[str] = field(default=frozenset(), compare=False)

    def get(self, part: str) -> Any:
        """The part ``part``; raises :class:`InputError` when it was not computed."""
        if part not in PARTS:
            raise InputError(f"unknown study part {part!r}; parts: {', '.join(PARTS)}")
        if part not in self.parts:
            raise InputError(
                f"the study did not compute the part {part!r} (computed: "
                f"{', '.join(p for p in PARTS if p in self.parts) or 'none'}); ask for it "
                "with study(config, parts=...)"
            )
        return getattr(self, part)

    @property
    def name(self) -> str:
        """The stage's name: the plant's, else the stage file's stem."""
        return self.config.plant.name or Path(self.config.source).stem

    def to_dict(self) -> dict[str, Any]:
        """``certificate.json``: the certificates, the envelope, firmware gains and the sections.

        Needs :data:`CERTIFICATE_PARTS`; the report's own sections
        (:data:`REPORT_SECTIONS`) are added when computed and applicable.
        """
        for part in sorted(CERTIFICATE_PARTS):
            self.get(part)
        config, synth = self.config, self.synthesis.result
        doc: dict[str, Any] = {
            "config": {"source": Path(config.source).name, "sha256": config.sha256},
            "envelope": self.envelope.to_dict(),
            "configured": None if self.configured is None else self.configured.to_dict(),
            "synthesized": None if synth.report is None else synth.report.to_dict(),
            "synthesis": self.synthesis.to_dict(),
            "firmware": self.firmware.to_dict(),
            "input": self.input.to_dict(),
            "units": _units(config.plant),
        }
        for part in REPORT_SECTIONS:
            value = getattr(self, part)
            if value is not None:
                doc[part] = value.to_dict()
        return doc


def _units(params: BoucWenParams) -> dict[str, Any]:
    """The units of the numbers in ``certificate.json`` (from the stage's length/input unit)."""
    iu = params.input_unit
    return {
        "length": params.length_unit,
        "input": iu,
        "udot_max": f"{iu}/s",
        "max_udot": f"{iu}/s",
        "decay": "1/s",
        "decay_rate": "1/s",
        "gains": ["1/s", "1/s^2", "1/s"],
        "dt": "s",
        "pole_radius": "rad/s",
    }
