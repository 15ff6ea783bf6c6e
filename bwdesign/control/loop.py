"""The closed loop as one typed object: every simulation, sweep, check and export takes it.

A :class:`ClosedLoop` is the plant *model* the observer and the law are built on, the
observer (:class:`~bwdesign.observers.spec.ObserverSpec`), the tracking controller
(:class:`~bwdesign.control.controllers.TrackingController` or its discrete form, with
its input limits, estimate clipping and integral action), the sample time, the
one-sample computation delay and the start. It is validated once, when it is built;
what a run adds (the reference, the true plant, noise, a duration) is an argument of
the simulation, not part of the loop.

A stage file builds its loops in one place, :meth:`ClosedLoop.from_config`: the
``[controller]`` law (eq. 12) or a digital tuning's, the ``[observer]`` gains or the
tuning's, the ``[controller]`` input limits, the ``[sampling]`` dt.

A loop with a baseline controller (:class:`~bwdesign.control.baselines.BaselineController`:
PI or PID on the measured output, with or without a hysteresis feedforward) has no
observer: ``observer=None``, stated, not faked (:attr:`ClosedLoop.baseline`). Its stage
loop is :meth:`ClosedLoop.baseline_from_config`. What needs an estimate (the continuous
simulation, the loop analysis of eq. 12, the certificates) refuses it through
:meth:`ClosedLoop.require_observer`.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConfigError, InputError
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_sample_time
from ..model.references import Reference
from ..observers.gains import check_disturbance_gains, check_gains
from ..observers.spec import ObserverSpec
from ..validate import SIGNAL, Range, real
from .baseline_tuning import make_baseline
from .baselines import BaselineController
from .controllers import TrackingController, TuningWarning, make_controller

__all__ = ["ClosedLoop", "Start", "ON_REFERENCE", "DIVERGENCE_LIMIT", "controller_from_config"]

#: ``start=ON_REFERENCE``: begin on the reference (:meth:`Start.on_reference`).
ON_REFERENCE = "reference"
#: Default: ``|x1|``, ``|x3|`` (and estimates) above this many length units, or ``|x2|`` above
#: it times sqrt(a1), count as divergence.
DIVERGENCE_LIMIT = 1e6
_POSITIVE = Range(0.0, math.inf, lo_open=True)


@dataclass(frozen=True)
class Start:
    """Initial plant state, estimate and the input held before ``t = 0``.

    Parameters
    ----------
    x0, xhat0 : tuple of 3 floats
        Plant state and estimate ``(x1, x2, x3)`` (length unit, length unit/s, length
        unit). A 4-state observer starts its disturbance estimate at 0.
    u_prev : float
        Input held before ``t = 0`` (input unit).
    """

    x0: tuple[float, float, float] = (0.0, 0.0, 0.0)
    xhat0: tuple[float, float, float] = (0.0, 0.0, 0.0)
    u_prev: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x0", "xhat0"):
            object.__setattr__(self, name, _state(getattr(self, name), name))
        object.__setattr__(self, "u_prev", real(self.u_prev, "u_prev", within=SIGNAL))

    @classmethod
    def on_reference(cls, params: BoucWenParams, reference: Reference) -> Start:
        """State, estimate and held input that put the loop on the reference at ``t = 0``.

        ``x0 = xhat0 = (x_d(0), x_d'(0), 0)``, ``u_prev`` the feedforward input that
        holds that state with no hysteresis, ``(x_d''(0) + a2 x_d'(0) + a1 x_d(0)) / a3``.
        """
        if not isinstance(reference, Reference):
            raise InputError(
                "reference must be a bwdesign Reference (Sine, Triangle, Step or a subclass), "
                f"got {reference!r}"
            )
        xd0, vd0, ad0 = (float(np.asarray(a)) for a in reference.evaluate(0.0))
        return cls(
            x0=(xd0, vd0, 0.0),
            xhat0=(xd0, vd0, 0.0),
            u_prev=(ad0 + params.a2 * vd0 + params.a1 * xd0) / params.a3,
        )

    def to_dict(self) -> dict[str, Any]:
        return {"x0": list(self.x0), "xhat0": list(self.xhat0), "u_prev": self.u_prev}


def _state(value: Any, name: str) -> tuple[float, float, float]:
    try:
        values = [float(v) for v in value]
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a finite vector of shape (3,), got {value!r}") from None
    if len(values) != 3:
        raise InputError(f"{name} must be a finite vector of shape (3,), got {value!r}")
    return tuple(real(v, f"{name}[{i}]", within=SIGNAL) for i, v in enumerate(values))


@dataclass(frozen=True)
class ClosedLoop:
    """The sampled (or continuous) tracking loop: model, observer, law, timing and start.

    Parameters
    ----------
    model : BoucWenParams
        The model the observer and the law are built on (the simulated plant is an
        argument of a simulation: ``true_params``).
    observer : ObserverSpec or None
        ``None`` exactly when ``controller`` is a baseline (it has no observer).
    controller : TrackingController or BaselineController
        Continuous eq. (12) or its discrete form; its ``u_limits``, ``estimate_limits``,
        ``hysteresis_jump`` and integral action apply. A simulation runs a copy. Or a
        baseline (PI/PID on the measurement, built for ``dt``).
    dt : float or None
        Sample time (s); ``None`` for a loop only simulated in continuous time.
    delay : bool
        One-sample computation delay.
    compensate_delay : bool
        With ``delay``, the law uses the one-step prediction.
    start : Start or "reference"
        Initial conditions; ``"reference"`` (:data:`ON_REFERENCE`) starts on the
        reference the loop is run with.
    divergence_limit : float
        ``|x1|``, ``|x3|`` and their estimates above this (length unit), or ``|x2|`` above it
        times ``sqrt(a1)``, count as divergence.
    allow_unbounded : bool
        Accept models (and true plants) outside the bounded class.

    Raises
    ------
    InputError, GainError, UnboundedModelError
        A malformed or inconsistent loop: wrong types, a controller built for another
        dt, gains that are not Hurwitz for ``model``, ``hysteresis_jump`` without an
        observer that has the hysteresis model.
    """

    model: BoucWenParams
    observer: ObserverSpec | None
    controller: TrackingController | BaselineController
    dt: float | None = None
    delay: bool = False
    compensate_delay: bool = True
    start: Start | str = dataclasses.field(default_factory=Start)
    divergence_limit: float = DIVERGENCE_LIMIT
    allow_unbounded: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.model, BoucWenParams):
            raise InputError(f"model must be a BoucWenParams, got {type(self.model).__name__}")
        require_bounded(self.model, self.allow_unbounded)
        if isinstance(self.controller, BaselineController):
            self._check_baseline()
        else:
            self._check_observer_loop()
        if not (isinstance(self.start, Start) or self.start == ON_REFERENCE):
            raise InputError(f"start must be a Start or {ON_REFERENCE!r}, got {self.start!r}")
        limit = real(self.divergence_limit, "divergence_limit", within=_POSITIVE)
        object.__setattr__(self, "divergence_limit", limit)
        for flag in ("delay", "compensate_delay", "allow_unbounded"):
            object.__setattr__(self, flag, bool(getattr(self, flag)))

    def _check_baseline(self) -> None:
        if self.observer is not None:
            raise InputError(
                "a baseline controller (PI/PID on the measurement) runs without an observer: "
                f"give observer=None, got {self.observer!r}"
            )
        if self.dt is None:
            raise InputError("a baseline controller runs sampled: give the loop's dt")
        object.__setattr__(self, "dt", check_sample_time(self.model, self.dt))
        if self.controller.dt != self.dt:
            raise InputError(
                f"the baseline controller was built for dt = {self.controller.dt:g} s, not "
                f"{self.dt} s"
            )

    def _check_observer_loop(self) -> None:
        if self.observer is None:
            raise InputError(
                "observer=None is for a baseline controller; the eq. (12) law needs an "
                "observer (ObserverSpec.of(kind, gains))"
            )
        if not isinstance(self.observer, ObserverSpec):
            raise InputError(
                f"observer must be an ObserverSpec (ObserverSpec.of(kind, gains)), got "
                f"{self.observer!r}"
            )
        if not isinstance(self.controller, TrackingController):
            raise InputError(
                f"controller must be a TrackingController, got {type(self.controller).__name__}"
            )
        if self.dt is not None:
            object.__setattr__(self, "dt", check_sample_time(self.model, self.dt))
        cdt = getattr(self.controller, "dt", None)
        if cdt is not None and cdt != self.dt:
            raise InputError(
                f"the discrete controller was built for dt = {cdt:g} s, not {self.dt} s"
            )
        obs = self.observer
        if obs.kind in ("phso", "eso"):
            check_gains(self.model, obs.gains)
        elif obs.four_state:
            check_disturbance_gains(self.model, obs.gains)
        if self.controller.hysteresis_jump and obs.kind == "eso":
            raise InputError(
                "hysteresis_jump needs an observer with the hysteresis model (PHSO); the ESO "
                "has none"
            )
        if self.controller.hysteresis_jump and obs.four_state:
            raise InputError(
                "hysteresis_jump is not implemented for the disturbance observer (PHDO): its "
                "law would need the jump of x3 with d added; use the PHSO or a law without "
                "the jump"
            )

    @property
    def baseline(self) -> bool:
        """The loop runs a baseline controller (and no observer)."""
        return isinstance(self.controller, BaselineController)

    def require_observer(self, what: str) -> None:
        """Raise :class:`InputError` naming ``what`` when the loop is a baseline."""
        if self.baseline:
            raise InputError(
                f"{what} needs an observer-based loop; the {self.controller.kind} baseline has "
                "no observer (simulate it with bwdesign.simulate or simulate_batch)"
            )

    # -- building ----------------------------------------------------------------

    @classmethod
    def from_config(
        cls,
        config: Any,
        *,
        observer: str = "phso",
        gains: Any = None,
        law: Any = None,
        form: str = "continuous",
        start: Start | str = ON_REFERENCE,
        saturate: bool = True,
        allow_unbounded: bool = False,
    ) -> ClosedLoop:
        """The loop a stage file describes: the one place a stage's loop is assembled.

        Parameters
        ----------
        config : bwdesign.model.config.StageConfig
            Needs ``[sampling]``; ``[controller]`` for its input limits and, without
            ``law``, its eq. (12) constants.
        observer : {"phso", "eso", "phdo", "ukf"}
        gains : sequence, optional
            The observer's design gains (3, or the PHDO's 4); default the tuning's
            (with ``law``) or the file's ``[observer]`` gains.
        law : DigitalTuning, optional
            A digital tuning (``lambda1``, ``lambda2``, ``integral_rate``, ``delay``,
            ``gains``): the discrete law with its integral action and delay. Default:
            eq. (12) with the ``[controller]`` constants in ``form``, no delay.
        form : {"continuous", "discrete"}
            The form of eq. (12) without ``law``.
        start : Start or "reference"
        saturate : bool
            Apply the ``[controller]`` input limits (``False``: the unsaturated loop a
            robust certificate covers).
        allow_unbounded : bool
        """
        controller = controller_from_config(config, law=law, form=form, saturate=saturate)
        design, delay = (config.gains, False) if law is None else (law.gains, bool(law.delay))
        if gains is not None:
            design = gains
        if observer != "ukf" and design is None:
            raise ConfigError(
                f"{config.source or 'config'}: the {observer.upper()} needs observer gains "
                "([observer] gains)"
            )
        spec = ObserverSpec.of(observer, None if observer == "ukf" else design)
        return cls(
            model=config.plant,
            observer=spec,
            controller=controller,
            dt=float(config.dt),
            delay=delay,
            start=start,
            allow_unbounded=allow_unbounded,
        )

    @classmethod
    def baseline_from_config(
        cls,
        config: Any,
        kind: str,
        *,
        gains: Any = None,
        phase_margin: float = 60.0,
        delay: bool = False,
        start: Start | str = ON_REFERENCE,
        saturate: bool = True,
        allow_unbounded: bool = False,
    ) -> ClosedLoop:
        """The stage's loop with the baseline ``kind`` (``"pi"``, ``"pid"``, ``"pi-bwff"``,
        ``"pi-piff"``) and no observer.

        Tuned on ``[plant]`` by :func:`~bwdesign.control.baseline_tuning.tune_baseline`
        (``phase_margin``, for the ``delay``) unless ``gains`` are given; the
        ``[controller]`` input limits apply unless ``saturate=False``; the Prandtl–Ishlinskii
        operator is fitted over the ``[reference]``'s range.
        """
        where = config.source or "config"
        if config.dt is None:
            raise ConfigError(f"{where}: the loop needs [sampling] dt")
        ctl = config.controller
        limits = ctl.input_limits() if ctl is not None and saturate else None
        controller = make_baseline(
            config.plant,
            float(config.dt),
            kind,
            reference=config.reference,
            gains=gains,
            phase_margin=phase_margin,
            delay=delay,
            u_limits=limits,
            allow_unbounded=allow_unbounded,
        )
        return cls(
            model=config.plant,
            observer=None,
            controller=controller,
            dt=float(config.dt),
            delay=delay,
            start=start,
            allow_unbounded=allow_unbounded,
        )

    def replace(self, **changes: Any) -> ClosedLoop:
        """A copy with ``changes`` (validated again)."""
        return dataclasses.replace(self, **changes)

    # -- what a run needs ----------------------------------------------------------

    def initial(self, reference: Reference) -> Start:
        """The start of a run with ``reference`` (resolves ``"reference"``)."""
        if isinstance(self.start, Start):
            return self.start
        return Start.on_reference(self.model, reference)

    @property
    def input_limits(self) -> tuple[float, float] | None:
        """The controller's ``(u_min, u_max)`` (input unit), or ``None``."""
        lim = self.controller.u_limits
        return None if lim is None else (float(lim[0]), float(lim[1]))

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.model.name,
            "observer": None if self.observer is None else self.observer.to_dict(),
            "controller": self.controller.to_dict(),
            "dt": self.dt,
            "delay": self.delay,
            "compensate_delay": self.compensate_delay,
            "start": self.start.to_dict() if isinstance(self.start, Start) else self.start,
            "divergence_limit": self.divergence_limit,
        }


def controller_from_config(
    config: Any, *, law: Any = None, form: str = "continuous", saturate: bool = True
) -> TrackingController:
    """A stage's tracking law: the one place it is built from a file.

    ``law=None``: eq. (12) with the ``[controller]`` constants in ``form``; a digital
    tuning: its discrete law with integral action. The ``[controller]`` input limits
    apply unless ``saturate=False``; ``dt`` is the ``[sampling]`` dt.

    Raises
    ------
    ConfigError
        No ``[sampling]`` dt, or no ``[controller]`` without ``law``.
    """
    where = config.source or "config"
    if config.dt is None:
        raise ConfigError(f"{where}: the loop needs [sampling] dt")
    ctl = config.controller
    limits = ctl.input_limits() if ctl is not None and saturate else None
    if law is None:
        if ctl is None:
            raise ConfigError(f"{where}: the loop needs [controller] lambda1, lambda2")
        lambdas, kw = (ctl.lambda1, ctl.lambda2), {"form": form}
    else:
        lambdas = (float(law.lambda1), float(law.lambda2))
        rate = None if law.integral_rate is None else float(law.integral_rate)
        kw = {"form": "discrete", "integral_rate": rate}
    with warnings.catch_warnings():  # a stage's own constants: the law is as given
        warnings.simplefilter("ignore", TuningWarning)
        return make_controller(config.plant, *lambdas, dt=float(config.dt), u_limits=limits, **kw)
