"""Computing a study: :func:`study` runs each asked part once, its dependencies first.

Every part is computed by one function here (or in its module: tiers, tracking,
sweep, robust, verdict), the same way whoever asks: the report asks for
:data:`~bwdesign.study.result.REPORT_PARTS`, ``bwdesign check`` and
:mod:`bwdesign.testing` for the parts their requirements read.
"""

from __future__ import annotations

import platform
from collections.abc import Callable, Iterable
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from .. import interrupts
from ..certify.linear import error_dynamics, hysteresis_bode
from ..certify.tiers import certify
from ..control.analysis import analyze_loop
from ..control.loop import ClosedLoop
from ..design.gains import synthesize
from ..design.tuning import digital_tuning
from ..errors import ConfigError, InputError
from ..model.config import StageConfig
from ..model.params import require_bounded
from ..model.summary import plant_summary
from ..observers.gains import check_gains, discrete_gains
from . import background
from .baselines import baseline_comparison, configured_baseline
from .cache import StudyCache
from .result import (
    DEFAULT_DECAY,
    PARTS,
    REPORT_PARTS,
    CornerTracking,
    Firmware,
    GainSetDynamics,
    InputRange,
    LoopStudy,
    PlantSummary,
    Study,
    StudySettings,
    Synthesis,
    TierSynthesisStudy,
)
from .robust import begin_robust_study
from .sweep import check_stage_sweep, stage_sweep
from .tiers import SEARCH_RTOL, synthesize_per_tier
from .tracking import corner_tracking, input_limits, required_input, tracking_runs
from .verdict import recommend, verdict

__all__ = ["study", "versions", "synthesis_request"]

#: The libraries whose versions a study records (beside Python's).
LIBRARIES = (
    "bwdesign",
    "numpy",
    "scipy",
    "cvxpy",
    "clarabel",
    "scs",
    "control",
    "filterpy",
    "matplotlib",
)

#: Stage sections a part needs (besides [plant]), with what each section is for.
SECTIONS = {
    "dt": "[sampling] (dt)",
    "envelope": "[envelope] (udot_max or from_reference)",
    "reference": "[reference] (the trajectory simulated at the envelope)",
    "controller": "[controller] (lambda1, lambda2)",
    "baseline": "[baseline] (kind; bwdesign init writes an example)",
}
_LOOP = ("dt", "envelope", "reference", "controller")
NEEDS: dict[str, tuple[str, ...]] = {
    "plant": (),
    "envelope": ("envelope",),
    "input": ("envelope", "reference"),
    "configured": ("envelope",),
    "synthesis": ("envelope",),
    "tuning": ("dt",),
    "tracking": _LOOP,
    "verdict": _LOOP,
    "tier_synthesis": ("envelope",),
    "error_dynamics": ("envelope",),
    "loop": ("dt", "controller"),
    "sweep": (),
    "robust": ("dt", "envelope", "reference"),
    "firmware": ("dt", "envelope"),
    "recommendation": _LOOP,
    "versions": (),
    "corner_tracking": ("dt", "reference", "controller"),
    "baselines": _LOOP,
    "baseline": ("dt", "baseline"),
}
#: Parts computed from the ``[observer]`` gains (checked to be Hurwitz before any work).
USES_GAINS = frozenset(
    ("configured", "tracking", "verdict", "error_dynamics", "loop", "firmware")
    + ("recommendation", "corner_tracking", "baselines")
)

#: Parts computed for any plant (the linear analyses); the others need the bounded class.
ANY_PLANT = frozenset(("plant", "tuning", "loop", "versions"))

_CERTIFYING = "certifying the configured gains and synthesising a certified set"
_TIERS = "synthesis per tier (the largest envelope synthesised gains reach)"

#: Parts a second process computes beside the others (``study(workers=2)``): the
#: synthesised gains, the configured gains' certificate and the per-tier synthesis read the
#: envelope alone (the synthesis first: a stage without gains tracks with its gains).
#: The robust section reads the tuning, so it is computed once the tuning is there, by
#: two children forked then, each certifying every second loop (robust_study(workers=)):
#: the second process computed the tuning once more when it had the section whole, and
#: the section then took as long as the rest (stack_actuator_800hz: the report 14.1 s;
#: 10.4 s split).
BESIDE = ("synthesis", "configured", "tier_synthesis")
#: Parts that read :data:`BESIDE`'s: computed after the others, when the second process
#: has had the time to send them.
_AFTER_BESIDE = ("verdict", "error_dynamics", "firmware")


class _Run:
    """One study being computed: the parts done so far, each computed on first use."""

    def __init__(
        self,
        config: StageConfig,
        allow_unbounded: bool,
        settings: StudySettings,
        progress: Callable[[str], None] | None,
        workers: int = 1,
    ) -> None:
        self.config = config
        self.workers = workers
        self.params = config.plant
        self.allow_unbounded = allow_unbounded
        self.settings = settings
        self.progress = progress
        self.done: dict[str, Any] = {}
        self._said: set[str] = set()
        self.beside: background.Background | None = None

    def compute(self, part: str) -> Any:
        """The part ``part``: computed before, sent by the second process, or computed now."""
        if part not in self.done:
            interrupts.check()  # a Ctrl-C a library swallowed: no part begins after it
            got, value = False, None
            if self.beside is not None and part in self.beside.keys:
                got, value = self.beside.result(part)
            self.done[part] = value if got else _COMPUTE[part](self)
        value = self.done[part]
        if isinstance(value, background.Pending):  # begun beside (begin): waited for now
            del self.done[part]
            value = self.done[part] = value.result()
        return value

    def begin(self, part: str) -> None:
        """Begin ``part`` where it can be computed beside this process while this one goes
        on (:data:`_BEGUN`; :meth:`compute` then waits for it), else compute it now."""
        if part in _BEGUN and self.workers >= 2 and part not in self.done:
            interrupts.check()
            self.done[part] = _BEGUN[part](self)
        else:
            self.compute(part)

    def give_up(self) -> None:
        """Stop what computes the parts begun and not waited for (an error, or Ctrl-C)."""
        for part, value in list(self.done.items()):
            if isinstance(value, background.Pending):
                del self.done[part]
                value.close()

    def settle_before(self, failed: str, asked: frozenset[str]) -> None:
        """Compute the asked :data:`BESIDE` parts that :data:`PARTS` puts before ``failed``.

        With a second process at work the parts are computed in another order; a part
        that fails then raises only after those, so the error is the one computing the
        parts in :data:`PARTS`' order raises first.
        """
        begun = [p for p, v in self.done.items() if isinstance(v, background.Pending)]
        for p in PARTS:
            before = PARTS.index(p) < PARTS.index(failed)
            if before and p in asked and (p in begun or (self.beside and p in BESIDE)):
                self.compute(p)

    def start_beside(self, asked: frozenset[str]) -> None:
        """Fork the second process for the asked :data:`BESIDE` parts not computed yet."""
        parts = [p for p in BESIDE if p in asked and p not in self.done]
        if not parts:
            return

        def quietly(part: str) -> Callable[[], Any]:
            def task() -> Any:
                self.progress = None  # in the child: this process says what it does
                return self.compute(part)

            return task

        if "robust" in asked:  # cvxpy, which both processes use, loaded once before the fork
            from ..certify import lmi  # noqa: F401

        self.beside = background.start([(p, quietly(p)) for p in parts])
        if self.beside is not None:
            for p in parts:
                self.say(_TIERS if p == "tier_synthesis" else _CERTIFYING)

    __getitem__ = compute

    def say(self, message: str) -> None:
        """A progress line (once per message)."""
        if self.progress is not None and message not in self._said:
            self._said.add(message)
            self.progress(message)

    @property
    def dt(self) -> float | None:
        return self.config.dt

    @property
    def udot_max(self) -> float:
        return self["envelope"].udot_max

    def loop_gains(self) -> Any:
        """The gains of the loop: the ``[observer]`` gains, else the synthesised ones."""
        if self.config.gains is not None:
            return self.config.gains
        return self["synthesis"].result.gains


def synthesis_request(config: StageConfig) -> tuple[float, float | None]:
    """The decay (1/s) and pole radius (rad/s) ``[synthesis]`` asks (decay default 100 1/s)."""
    spec = config.synthesis or {}
    return spec.get("decay", DEFAULT_DECAY), spec.get("pole_radius")


def versions() -> dict[str, str]:
    """Python's version and each of :data:`LIBRARIES`' ("not installed" when absent)."""
    out = {"python": platform.python_version()}
    for pkg in LIBRARIES:
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "not installed"
    return out


# -- the parts ---------------------------------------------------------------------


def _plant(r: _Run) -> PlantSummary:
    summ = plant_summary(r.params)
    d, bc = summ["derived"], summ["bounded_class"]
    return PlantSummary(
        params=r.params,
        natural_frequency_hz=d["natural_frequency_hz"],
        damping_ratio=d["damping_ratio"],
        static_gain=d["static_gain"],
        static_gain_unit=d["static_gain_unit"],
        bounded=bc["bounded"],
        bounded_reason=bc["reason"],
        note=summ.get("note"),
    )


def _envelope(r: _Run) -> Any:
    return r.config.envelope(allow_unbounded=r.allow_unbounded)


def _input(r: _Run) -> InputRange:
    limits = input_limits(r.config)
    need = required_input(r.config, r["envelope"], allow_unbounded=r.allow_unbounded)
    within = None
    if limits is not None and need is not None:
        within = bool(limits[0] <= need[0] and need[1] <= limits[1])
    return InputRange(limits=limits, feedforward=need, within_limits=within)


def _configured(r: _Run) -> Any:
    r.say(_CERTIFYING)
    if r.config.gains is None:
        return None
    return certify(
        r.params,
        r.config.gains,
        udot_max=r.udot_max,
        decay=r.settings.decay,
        dt=r.dt,
        allow_unbounded=r.allow_unbounded,
    )


def _synthesis(r: _Run) -> Synthesis:
    r.say(_CERTIFYING)
    decay, pole_radius = synthesis_request(r.config)
    res = synthesize(
        r.params,
        udot_max=r.udot_max,
        decay=decay,
        pole_radius=pole_radius,
        dt=r.dt,
        allow_unbounded=r.allow_unbounded,
    )
    return Synthesis(decay=decay, pole_radius=pole_radius, result=res)


def _tuning(r: _Run) -> Any:
    return digital_tuning(r.params, r.dt)


def _tracking(r: _Run) -> Any:
    gains, tuning = r.loop_gains(), r["tuning"]
    r.say("simulating the tracking loop at the envelope (PHSO, ESO and PHDO)")
    return tracking_runs(r.config, gains=gains, tuning=tuning, allow_unbounded=r.allow_unbounded)


def _verdict(r: _Run) -> Any:
    synth = r["synthesis"].result
    return verdict(r.config, r["configured"], synth, r.udot_max, r["input"], r["tracking"])


def _tier_synthesis(r: _Run) -> TierSynthesisStudy:
    r.say(_TIERS)
    decay, pole_radius = synthesis_request(r.config)
    rows = synthesize_per_tier(
        r.params,
        udot_max=r.udot_max,
        decay=decay,
        dt=r.dt,
        pole_radius=pole_radius,
        allow_unbounded=r.allow_unbounded,
    )
    return TierSynthesisStudy(
        udot_max=r.udot_max, decay=rows[0].decay, search_rtol=SEARCH_RTOL, rows=tuple(rows)
    )


def _error_dynamics(r: _Run) -> tuple[GainSetDynamics, ...]:
    synth = r["synthesis"].result
    r.say("linear analysis of the observer error dynamics")
    sets = {}
    if r.config.gains is not None:
        sets["configured"] = r.config.gains
    if synth.gains is not None:
        sets["synthesised"] = synth.gains
    out = []
    for label, g in sets.items():
        ed = error_dynamics(r.params, g, udot_max=r.udot_max)
        out.append(GainSetDynamics(label, tuple(g), ed, hysteresis_bode(r.params, g)))
    return tuple(out)


def _loop(r: _Run) -> LoopStudy:
    gains = r.loop_gains()
    r.say("tracking-loop analysis (continuous, sampled, digital tuning)")
    ctl = r.config.controller
    sampled = ClosedLoop.from_config(
        r.config, gains=gains, saturate=False, allow_unbounded=r.allow_unbounded
    )
    return LoopStudy(
        lambda1=ctl.lambda1,
        lambda2=ctl.lambda2,
        gains=tuple(gains),
        continuous=analyze_loop(sampled.replace(dt=None)),
        sampled=analyze_loop(sampled),
    )


def _sweep(r: _Run) -> Any:
    if r.config.sweep is None:
        return None
    r.say(f"Monte Carlo sweep over [uncertainty]: {r.config.sweep['samples']} scenarios")
    return stage_sweep(r.config)


#: What computing the robust part says: over the stage's box, or the nominal loop alone.
_ROBUST_BOX = "robust certificate over [uncertainty] (every corner) and of the nominal loop"
_ROBUST_NOMINAL = "certificate of the nominal loop"


def _robust_says(r: _Run) -> str | None:
    """What computing the robust part says (None: there is nothing to certify)."""
    box = r.config.uncertainty
    if box is None or box.undetermined():
        if not r.params.bounded_class().bounded:  # (--allow-unbounded): nothing to certify
            return None
        return _ROBUST_NOMINAL
    return _ROBUST_BOX


def _robust(r: _Run, begin: bool = False) -> Any:
    """The robust section; ``begin``: begun by two children (:meth:`_Run.begin`), its
    value a :class:`~bwdesign.study.background.Pending` this process waits for later."""
    says = _robust_says(r)
    if says is None:
        return None
    tuning = r["tuning"]
    r.say(says)
    begun = begin_robust_study(r.config, tuning, r.udot_max, workers=r.workers if begin else 1)

    def section() -> Any:
        try:
            return begun.result()
        except InputError:
            if says == _ROBUST_BOX:
                raise
            return None  # a stage without a box: the nominal certificate alone, where it applies

    return background.Pending(section, begun.close) if begin else section()


def _firmware(r: _Run) -> Firmware:
    configured, synth = r["configured"], r["synthesis"].result
    gains = r.config.gains

    def floats(k: Any) -> tuple[float, ...] | None:
        return None if k is None else tuple(float(v) for v in k)

    return Firmware(
        dt=r.dt,
        configured_K=None if configured is None else floats(configured.discrete_gains),
        synthesized_K=floats(synth.discrete_gains),
        pole_matched=None if gains is None else floats(discrete_gains(r.params, gains, r.dt)),
    )


def _recommendation(r: _Run) -> Any:
    return recommend(r["tuning"], r["tracking"])


def _corner_tracking(r: _Run) -> CornerTracking:
    s = r.settings
    duration, plants, res = corner_tracking(
        r.config,
        observer=s.observer,
        noise_std=s.noise_std,
        duration=s.duration,
        start=s.start,
        mismatch=s.mismatch,
        allow_unbounded=r.allow_unbounded,
    )
    return CornerTracking(settings=s, duration=duration, plants=plants, result=res)


def _baselines(r: _Run) -> Any:
    r.say("baseline controllers beside the observer loops (nominal and worst corner)")
    return baseline_comparison(
        r.config,
        gains=r.loop_gains(),
        tuning=r["tuning"],
        tracking=r["tracking"],
        allow_unbounded=r.allow_unbounded,
    )


#: Parts :meth:`_Run.begin` begins beside this process (``workers >= 2``): the robust
#: section's loops, certified by two children while this process computes the parts
#: after it (the baselines); then it waits for them.
_BEGUN: dict[str, Callable[[_Run], Any]] = {"robust": lambda r: _robust(r, begin=True)}

_COMPUTE: dict[str, Callable[[_Run], Any]] = {
    "plant": _plant,
    "envelope": _envelope,
    "input": _input,
    "configured": _configured,
    "synthesis": _synthesis,
    "tuning": _tuning,
    "tracking": _tracking,
    "verdict": _verdict,
    "tier_synthesis": _tier_synthesis,
    "error_dynamics": _error_dynamics,
    "loop": _loop,
    "sweep": _sweep,
    "robust": _robust,
    "firmware": _firmware,
    "recommendation": _recommendation,
    "versions": lambda r: versions(),
    "corner_tracking": _corner_tracking,
    "baselines": _baselines,
    "baseline": lambda r: configured_baseline(r.config, allow_unbounded=r.allow_unbounded),
}


# -- asking --------------------------------------------------------------------------


def _asked(parts: Iterable[str] | None) -> frozenset[str]:
    if parts is None:
        return REPORT_PARTS
    if isinstance(parts, str):
        parts = (parts,)
    try:
        asked = frozenset(parts)
    except TypeError:
        raise InputError(f"parts must be a collection of part names, got {parts!r}") from None
    unknown = sorted(asked - set(PARTS))
    if unknown:
        raise InputError(f"unknown study part(s) {unknown}; parts: {', '.join(PARTS)}")
    return asked


def _preflight(r: _Run, asked: frozenset[str]) -> None:
    """Every check that can end in an ``error:`` line, before any work (and progress line)."""
    config = r.config
    if asked - ANY_PLANT:
        require_bounded(r.params, r.allow_unbounded)
    needs = {s for p in asked for s in NEEDS[p]}
    if config.gains is None and asked & {"loop"}:
        needs.add("envelope")  # the loop runs the synthesised gains
    values = {
        "dt": config.dt,
        "envelope": config.envelope_spec,
        "reference": config.reference,
        "controller": config.controller,
        "baseline": config.baseline,
    }
    missing = [text for key, text in SECTIONS.items() if key in needs and values[key] is None]
    if missing:
        who = (
            "the report"
            if asked >= REPORT_PARTS
            else f"the study ({', '.join(p for p in PARTS if p in asked)})"
        )
        raise ConfigError(
            f"{config.source or 'config'}: {who} needs section(s) {', '.join(missing)}"
        )
    if "envelope" in needs:
        r.compute("envelope")
    if config.gains is not None and asked & USES_GAINS:
        check_gains(r.params, config.gains)
    if "sweep" in asked and config.sweep is not None:
        check_stage_sweep(config)


def _order(beside: bool) -> tuple[str, ...]:
    """The order to compute the parts: :data:`PARTS`', or with a second process at work
    (``beside``) the parts that read its parts after the others."""
    if not beside:
        return PARTS
    first = tuple(p for p in PARTS if p not in BESIDE and p not in _AFTER_BESIDE)
    return first + _AFTER_BESIDE + BESIDE


def study(
    config: StageConfig,
    *,
    allow_unbounded: bool = False,
    parts: Iterable[str] | None = None,
    progress: Callable[[str], None] | None = None,
    settings: StudySettings | None = None,
    cache: StudyCache | None = None,
    workers: int = 1,
) -> Study:
    """Compute the study of a stage: everything the certified-gains report shows.

    Parameters
    ----------
    config : StageConfig
    allow_unbounded : bool
        Accept a plant outside the bounded Bouc-Wen class.
    parts : collection of str, optional
        The parts to compute (names from :data:`~bwdesign.study.result.PARTS`; the parts
        they depend on are computed too). Default: every part the report shows.
    progress : callable, optional
        Called with a line of text as each long part starts.
    settings : StudySettings, optional
        What the checks ask beyond the file; default the stage's ``[requirements]``
        tracking settings, certificates at decay 0.
    cache : StudyCache, optional
        Read the parts kept for this very study (same stage file, settings, code and
        libraries: :mod:`bwdesign.study.cache`) instead of computing them, and keep
        the ones computed. Default: no cache.
    workers : int
        2 or more: a second process (forked, :mod:`bwdesign.study.background`)
        computes the certificates and the per-tier synthesis (:data:`BESIDE`) while
        this one computes the rest; the study is the same. Where no process can be
        forked safely (not Linux, or other threads running) this process computes all.

    Returns
    -------
    Study

    Raises
    ------
    ConfigError
        A section a part needs is missing, or ``[sweep]`` cannot run.
    GainError, UnboundedModelError, InputError
        Gains that are not Hurwitz, a plant outside the bounded class, bad parts.
    """
    if not isinstance(config, StageConfig):
        raise InputError(f"config must be a StageConfig, got {type(config).__name__}")
    if settings is None:
        settings = StudySettings.from_requirements(config.requirements)
    elif not isinstance(settings, StudySettings):
        raise InputError(f"settings must be a StudySettings, got {type(settings).__name__}")
    if cache is not None and not isinstance(cache, StudyCache):
        raise InputError(f"cache must be a StudyCache or None, got {type(cache).__name__}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers must be an integer >= 1, got {workers!r}")
    asked = _asked(parts)
    r = _Run(config, bool(allow_unbounded), settings, progress, workers)
    key, kept = None, {}
    if cache is not None:
        key = cache.key(config, r.allow_unbounded, settings, versions())
        kept = (cache.load(key) or {}) if key is not None else {}
        r.done.update(kept)
    _preflight(r, asked)
    if kept and asked <= set(kept):
        r.say(f"study read from the cache ({cache.store.root}; --no-cache computes it)")
    if workers >= 2:
        r.start_beside(asked)
    try:
        for part in _order(r.beside is not None) + PARTS:  # then: the parts begun
            if part in asked:
                try:
                    r.begin(part) if part not in r.done else r.compute(part)
                except Exception:
                    r.settle_before(part, asked)  # the error the order of PARTS meets first
                    raise
    finally:
        r.give_up()
        if r.beside is not None:
            r.beside.close()
    if key is not None and set(r.done) - set(kept):
        cache.save(key, r.done)
    return Study(
        config=config,
        allow_unbounded=r.allow_unbounded,
        settings=settings,
        parts=frozenset(r.done),
        cache_key=key,
        cached=frozenset(kept),
        **r.done,
    )
