"""Baseline controllers: what a user would keep instead of an observer-based loop.

A :class:`BaselineController` is a PI or PID controller on the *measured* output, with
an optional feedforward that inverts the hysteresis, and anti-windup on the input
limits. It needs no observer: a :class:`~bwdesign.control.loop.ClosedLoop` holding one
has ``observer=None`` (docs/design.md, section "Baseline controllers"). Four kinds,
the names of ``bwdesign simulate --controller``:

- ``"pi"``: ``u = Kp e + Ki q``, ``e = x_d - y``;
- ``"pid"``: plus a filtered derivative on the measurement (no derivative kick);
- ``"pi-bwff"``: PI plus the exact inverse of the Bouc–Wen model as feedforward (the
  inverse the envelope is derived with, :func:`bwdesign.model.inverse.inverse_input`: a
  safeguarded Newton iteration per sample that the C export repeats operation for operation);
- ``"pi-piff"``: PI plus the analytic inverse of a Prandtl–Ishlinskii operator
  (:mod:`bwdesign.model.prandtl`) fitted to the model's quasi-static record
  (:mod:`bwdesign.identify.prandtl`), applied to the quasi-static equivalent of the
  reference ``x_d + (a2 x_d' + x_d'')/a1`` (the linear part inverted with the model).

Per sample ``k`` (measurement ``z_k``, feedforward ``f_k``; :func:`pid_step`)::

    e_k = x_d(t_k) - z_k
    d_k = Tf/(Tf + dt) d_{k-1} - Kd/(Tf + dt) (z_k - z_{k-1})     (backward Euler)
    q'  = q_{k-1} + dt e_k
    v   = f_k + Kp e_k + Ki q' + d_k,     u_k = clip(v, u_min, u_max)
    q_k = q_{k-1} if (v > u_max and e_k > 0) or (v < u_min and e_k < 0) else q'

The last line is the anti-windup: conditional integration (clamping), the integrator
does not run further into a saturated limit, so ``Ki q`` stays within the limits'
span plus the proportional and feedforward terms. The feedforward is evaluated at
mid-sample (``t_k + dt/2``, the zero-order hold's half-sample lag; one sample later
with a computation delay). The integrator starts so that the first output equals the
input held before ``t = 0`` (bumpless start).

Gains are explicit (:meth:`BaselineController.__init__`) or chosen by the stated
rule of :func:`bwdesign.control.baseline_tuning.tune_baseline` (a phase margin at the
crossover on the sampled nominal linear model).
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from ..errors import GainError, InputError
from ..model.config import BASELINE_KINDS
from ..model.inverse import inverse_input
from ..model.params import BoucWenParams
from ..model.plant import check_dt
from ..model.prandtl import PrandtlIshlinskii
from ..model.references import Reference
from ..validate import NONNEGATIVE, POSITIVE, input_limits, real

__all__ = [
    "BaselineController",
    "InverseBoucWenFeedforward",
    "PrandtlFeedforward",
    "PIDState",
    "pid_step",
    "BASELINE_KINDS",
]


@functools.lru_cache(maxsize=8)
def _inverse_input(params, reference, t_bytes: bytes, allow_unbounded: bool) -> np.ndarray:
    t = np.frombuffer(t_bytes, dtype=float)
    u, _ = inverse_input(params, reference, t, allow_unbounded=allow_unbounded)
    u.setflags(write=False)
    return u


class InverseBoucWenFeedforward:
    """Feedforward by the exact inverse of the Bouc–Wen model ``params``.

    The input under which ``x1`` follows ``x_d`` exactly on the model, solved sample by
    sample from a zero hysteresis state (:func:`bwdesign.model.inverse.inverse_input`, the
    inverse the operating envelope is derived with; ``export-c --controller pi-bwff``
    writes the same iteration in C).
    """

    kind = "bwff"

    def __init__(self, params: BoucWenParams, *, allow_unbounded: bool = False) -> None:
        if not isinstance(params, BoucWenParams):
            raise InputError(f"params must be a BoucWenParams, got {type(params).__name__}")
        self.params = params
        self.allow_unbounded = bool(allow_unbounded)

    def samples(self, reference: Reference, t: np.ndarray) -> np.ndarray:
        """The feedforward input at the times ``t`` (s), input unit.

        The last few are kept (a run, its batch over the corners and a replay share one).
        """
        t = np.ascontiguousarray(t, dtype=float)
        key = (self.params, reference, t.tobytes(), self.allow_unbounded)
        try:
            return _inverse_input(*key).copy()
        except TypeError:  # a reference that cannot be hashed: computed each time
            u, _ = inverse_input(self.params, reference, t, allow_unbounded=self.allow_unbounded)
            return u

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "model": self.params.to_dict()}


class PrandtlFeedforward:
    """Feedforward by the analytic inverse of a Prandtl–Ishlinskii operator.

    ``operator`` maps the input to the quasi-static output (fitted by
    :func:`bwdesign.identify.prandtl.fit_prandtl_ishlinskii`); the feedforward is its
    inverse applied to ``x_d + (a2 x_d' + x_d'')/a1``, the output the hysteresis alone
    must give for the linear part (``a1``, ``a2`` of the model) to follow ``x_d``.

    Raises
    ------
    ParameterError
        The operator is not invertible.
    """

    kind = "piff"

    def __init__(self, operator: PrandtlIshlinskii, a1: float, a2: float) -> None:
        if not isinstance(operator, PrandtlIshlinskii):
            raise InputError(f"operator must be a PrandtlIshlinskii, got {type(operator).__name__}")
        self.operator = operator
        self.inverse = operator.inverse()
        self.a1 = real(a1, "a1", within=POSITIVE)
        self.a2 = real(a2, "a2", within=NONNEGATIVE)

    def samples(self, reference: Reference, t: np.ndarray) -> np.ndarray:
        """The feedforward input at the times ``t`` (s), input unit."""
        xd, vd, ad = (np.asarray(a, dtype=float) for a in reference.evaluate(np.asarray(t)))
        return self.inverse(xd + (self.a2 * vd + ad) / self.a1)

    def to_dict(self) -> dict[str, Any]:
        op = self.operator.to_dict()
        return {"kind": self.kind, "operator": op, "a1": self.a1, "a2": self.a2}


class PIDState:
    """The controller's state: integrator ``q``, derivative term ``d``, previous measurement."""

    __slots__ = ("q", "d", "zp")

    def __init__(self, q: Any, d: Any, zp: Any) -> None:
        self.q, self.d, self.zp = q, d, zp


def pid_step(c: Any, s: PIDState, z: Any, xd: Any, ff: Any, clip: Any) -> Any:
    """One sample of the law (module docstring) on floats or arrays; returns ``u_k``.

    ``c`` holds ``kp, ki, da, db, dt, lo, hi`` (:meth:`BaselineController.constants`);
    ``clip(v, lo, hi)`` is the element-wise clip of the caller (one run or a batch).
    """
    e = xd - z
    s.d = c.da * s.d - c.db * (z - s.zp)
    s.zp = z
    qn = s.q + c.dt * e
    v = ff + c.kp * e + c.ki * qn + s.d
    hold = (v > c.hi) * (e > 0) + (v < c.lo) * (e < 0)
    s.q = qn + hold * (s.q - qn)
    return clip(v, c.lo, c.hi)


class _Constants:
    __slots__ = ("kp", "ki", "da", "db", "dt", "lo", "hi")


class BaselineController:
    """PI or PID on the measured output, with an optional hysteresis feedforward.

    Parameters
    ----------
    kp : float
        Proportional gain (input unit per length unit), >= 0.
    ki : float
        Integral gain (input unit per length unit and second), > 0.
    dt : float
        Sample time (s).
    kd : float
        Derivative gain (input unit s per length unit), >= 0; 0 for a PI.
    tf : float, optional
        Derivative filter time constant (s), > 0; required with ``kd > 0``.
    u_limits : (float, float), optional
        Amplifier limits (input unit): the output is clipped, the integrator clamped.
    feedforward : InverseBoucWenFeedforward or PrandtlFeedforward, optional
    tuning : dict, optional
        How the gains were chosen (:func:`~bwdesign.control.baseline_tuning.tune_baseline`
        records its rule, target and margins here); ``None`` for explicit gains.

    Raises
    ------
    GainError
        A gain that is not a finite number in its range, ``kd > 0`` without ``tf``.
    InputError
        Malformed limits or feedforward.
    """

    form = "baseline"
    #: a baseline has no observer, so no hysteresis jump and no estimate clipping
    hysteresis_jump = False
    estimate_limits = None

    def __init__(
        self,
        kp: float,
        ki: float,
        *,
        dt: float,
        kd: float = 0.0,
        tf: float | None = None,
        u_limits: Any = None,
        feedforward: Any = None,
        tuning: dict | None = None,
    ) -> None:
        self.kp = real(kp, "kp", within=NONNEGATIVE, error=GainError)
        self.ki = real(ki, "ki", within=POSITIVE, error=GainError)
        self.kd = real(kd, "kd", within=NONNEGATIVE, error=GainError)
        self.dt = check_dt(dt)
        if self.kd > 0 and tf is None:
            raise GainError("a derivative gain kd > 0 needs the filter time constant tf (s)")
        self.tf = None if tf is None else real(tf, "tf (s)", within=POSITIVE, error=GainError)
        self.u_limits = input_limits(u_limits)
        if feedforward is not None and not isinstance(
            feedforward, InverseBoucWenFeedforward | PrandtlFeedforward
        ):
            raise InputError(
                "feedforward must be an InverseBoucWenFeedforward or a PrandtlFeedforward, got "
                f"{type(feedforward).__name__}"
            )
        self.feedforward = feedforward
        self.tuning = tuning

    @property
    def kind(self) -> str:
        """``"pi"``, ``"pid"``, ``"pi-bwff"`` or ``"pi-piff"`` (a PID with a feedforward:
        ``"pid-bwff"``, ``"pid-piff"``)."""
        base = "pid" if self.kd > 0 else "pi"
        return base if self.feedforward is None else f"{base}-{self.feedforward.kind}"

    def constants(self) -> _Constants:
        """The numbers :func:`pid_step` reads."""
        c = _Constants()
        c.kp, c.ki, c.dt = self.kp, self.ki, self.dt
        tf = self.tf or 0.0
        c.da = tf / (tf + self.dt) if self.kd > 0 else 0.0
        c.db = self.kd / (tf + self.dt) if self.kd > 0 else 0.0
        c.lo, c.hi = self.u_limits if self.u_limits else (-math.inf, math.inf)
        return c

    def feedforward_samples(self, reference: Reference, t: np.ndarray) -> np.ndarray:
        """The feedforward at the times ``t`` (zeros without one), input unit."""
        t = np.asarray(t, dtype=float)
        if self.feedforward is None:
            return np.zeros(t.shape)
        return np.asarray(self.feedforward.samples(reference, t), dtype=float)

    def start(self, y0: float, u_prev: float, ff0: float) -> PIDState:
        """The state that makes the first output ``u_prev`` (bumpless start)."""
        return PIDState((u_prev - ff0) / self.ki, 0.0, y0)

    def transfer(self) -> tuple[np.ndarray, np.ndarray]:
        """The feedback part from ``-y`` to ``u`` as ``(num, den)`` in ``z`` (descending).

        ``Kp + Ki dt z/(z - 1) + Kd/(Tf + dt) (z - 1)/(z - Tf/(Tf + dt))``.
        """
        c = self.constants()
        num = np.polyadd(np.array([c.kp, -c.kp]), np.array([c.ki * c.dt, 0.0]))
        den = np.array([1.0, -1.0])
        if self.kd > 0:
            pole = np.array([1.0, -c.da])
            num = np.polyadd(np.polymul(num, pole), c.db * np.polymul([1.0, -1.0], [1.0, -1.0]))
            den = np.polymul(den, pole)
        return num, den

    def reset(self) -> None:
        """Nothing to clear: a run's state lives in its :class:`PIDState`."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "form": self.form,
            "kind": self.kind,
            "kp": self.kp,
            "ki": self.ki,
            "kd": self.kd,
            "tf": self.tf,
            "dt": self.dt,
            "u_limits": list(self.u_limits) if self.u_limits else None,
            "anti_windup": "conditional integration (clamping)",
            "feedforward": None if self.feedforward is None else self.feedforward.to_dict(),
            "tuning": self.tuning,
        }

    def __repr__(self) -> str:
        return (
            f"BaselineController({self.kind!r}, kp={self.kp:g}, ki={self.ki:g}, kd={self.kd:g}, "
            f"dt={self.dt:g}, u_limits={self.u_limits})"
        )
