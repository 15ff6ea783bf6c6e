"""Tuning and linear analysis of the baseline controllers on the stage's nominal model.

The linear model (``G`` below) is the model's linear part with the hysteresis
replaced by its slope ``dh/du`` (``x3 = slope u``)::

    G(s) = (a3 - a1 slope) / (s^2 + a2 s + a1)

sampled exactly with a zero-order hold at ``dt`` (:func:`bwdesign.model.plant.discretize`),
times ``z^-1`` with a one-sample computation delay. The *tuning* slope is ``alpha``, the
hysteresis's slope from the demagnetised state (``x3 = 0``); along a loop the slope
ranges over ``[0, alpha + (beta - gamma) h_max]`` (saturated hysteresis, and just after
a reversal at ``|x3| = h_max``), so the loop gain varies by the factor
:attr:`BaselineAnalysis.gain_range`.

The tuning rule (:func:`tune_baseline`) is the loop-shaping rule of a phase margin at
the crossover (Åström and Murray, *Feedback Systems*, 2nd ed., Section 11.4) with fixed
corner ratios: the PI's integral corner a quarter of the crossover, ``Ti = 4/wc``; the
PID's also ``Td = 1/wc`` and a derivative filter ``Tf = Td/10``. The crossover ``wc``
is the frequency at which the sampled loop's phase is ``-180 deg + phase_margin``
(default 60 deg), and ``Kp`` makes ``|L(e^{j wc dt})| = 1`` there: the nominal loop has
exactly the stated phase margin at its crossover. The gain margin follows from the
plant and is measured (:func:`analyze_baseline`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import GainError, InputError
from ..model.params import BoucWenParams
from ..model.plant import discretize, hysteresis_slope_range
from ..validate import Range, real
from .baselines import BaselineController

__all__ = [
    "BaselineAnalysis",
    "analyze_baseline",
    "tune_baseline",
    "make_baseline",
    "sampled_plant",
    "slope_range",
    "PHASE_MARGIN",
    "TUNING_RULE",
]

#: Supported phase-margin targets (deg).
PHASE_MARGIN = Range(10.0, 85.0, unit="deg")
#: The rule, as the report and the JSON state it.
TUNING_RULE = (
    "phase margin {pm:g} deg at the crossover of the sampled nominal linear model "
    "(hysteresis slope alpha), Ti = 4/wc{pid}, Kp for |L| = 1 at wc"
)
_GRID = 4000


def slope_range(params: BoucWenParams) -> tuple[float, float]:
    """The slope ``dh/du`` over the bounded class: ``(0, alpha + (beta - gamma) h_max)``
    (:func:`bwdesign.model.plant.hysteresis_slope_range`)."""
    return hysteresis_slope_range(params)


def sampled_plant(
    params: BoucWenParams, dt: float, *, slope: float, delay: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """``G(z)`` (module docstring) as ``(num, den)`` in ``z``, descending powers."""
    zoh = discretize(params, dt)
    F = np.asarray(zoh.F[:2, :2])
    g = np.asarray(zoh.g[:2]) * (params.a3 - params.a1 * slope) / params.a3
    # G(z) = [1 0] (zI - F)^-1 g:  den = det(zI - F), num = adj(zI - F) first row . g
    den = np.array([1.0, -np.trace(F), np.linalg.det(F)])
    num = np.array([0.0, g[0], F[0, 1] * g[1] - F[1, 1] * g[0]])
    if delay:
        den = np.polymul(den, [1.0, 0.0])
        num = np.r_[0.0, num]
    return num, den


def _response(num: np.ndarray, den: np.ndarray, z: np.ndarray) -> np.ndarray:
    return np.polyval(num, z) / np.polyval(den, z)


@dataclass(frozen=True)
class BaselineAnalysis:
    """Margins and stability of a baseline's sampled nominal loop.

    Attributes
    ----------
    stable : bool
        Every closed-loop pole inside the unit circle at the tuning slope *and* at both
        ends of :func:`slope_range`.
    spectral_radius : float
        Largest closed-loop pole modulus at the tuning slope.
    worst_radius : float
        Largest over the three slopes.
    phase_margin : float or None
        Degrees, at the (first) gain crossover; None without one.
    crossover : float or None
        Gain-crossover frequency (rad/s).
    gain_margin : float or None
        Factor (not dB) at the first phase crossover below the Nyquist frequency; None
        without one (infinite).
    gain_range : float
        Largest over smallest loop gain across :func:`slope_range`.
    delay : bool
    """

    stable: bool
    spectral_radius: float
    worst_radius: float
    phase_margin: float | None
    crossover: float | None
    gain_margin: float | None
    gain_range: float
    delay: bool

    @property
    def gain_margin_db(self) -> float | None:
        return None if self.gain_margin is None else 20.0 * math.log10(self.gain_margin)

    def describe(self) -> str:
        """One line: stable or not, with the margins."""
        pm = "none" if self.phase_margin is None else f"{self.phase_margin:.3g} deg"
        wc = "" if self.crossover is None else f" at {self.crossover:.4g} rad/s"
        gm = "infinite" if self.gain_margin is None else f"{self.gain_margin_db:.3g} dB"
        head = "stable" if self.stable else "not stable"
        return (
            f"{head}: phase margin {pm}{wc}, gain margin {gm}, closed-loop pole radius "
            f"{self.spectral_radius:.6g} (worst over the hysteresis slope range "
            f"{self.worst_radius:.6g}, loop-gain range x{self.gain_range:.3g})"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "stable": self.stable,
            "spectral_radius": self.spectral_radius,
            "worst_radius": self.worst_radius,
            "phase_margin_deg": self.phase_margin,
            "crossover_rad_s": self.crossover,
            "gain_margin": self.gain_margin,
            "gain_margin_db": self.gain_margin_db,
            "gain_range": self.gain_range,
            "delay": self.delay,
        }


def _radius(cnum, cden, pnum, pden) -> float:
    char = np.polyadd(np.polymul(cden, pden), np.polymul(cnum, pnum))
    char = np.trim_zeros(char, "f")
    return float(np.max(np.abs(np.roots(char)))) if char.size > 1 else 0.0


def _margins(cnum, cden, pnum, pden, dt) -> tuple[Any, Any, Any]:
    w = np.geomspace(1e-3 / dt, math.pi / dt * (1 - 1e-9), _GRID)
    z = np.exp(1j * w * dt)
    L = _response(cnum, cden, z) * _response(pnum, pden, z)
    mag, ph = np.abs(L), np.unwrap(np.angle(L))
    pm = wc = gm = None
    cross = np.flatnonzero((mag[:-1] >= 1.0) & (mag[1:] < 1.0))
    if cross.size:
        i = int(cross[0])
        f = math.log(mag[i]) / (math.log(mag[i]) - math.log(mag[i + 1]))
        wc = float(w[i] * (w[i + 1] / w[i]) ** f)
        Lc = _response(cnum, cden, np.exp(1j * wc * dt)) * _response(
            pnum, pden, np.exp(1j * wc * dt)
        )
        phc = float(np.angle(Lc))
        # the unwrapped branch near the crossover
        phc += 2 * math.pi * round((ph[i] - phc) / (2 * math.pi))
        pm = math.degrees(phc) + 180.0
    k = (ph + math.pi) / (2 * math.pi)
    pc = np.flatnonzero(np.floor(k[:-1]) != np.floor(k[1:]))
    if pc.size:
        i = int(pc[0])
        edge = math.floor(max(k[i], k[i + 1]))  # the -180 deg (mod 360) line crossed
        f = (edge - k[i]) / (k[i + 1] - k[i])
        gm = float(1.0 / (mag[i] + f * (mag[i + 1] - mag[i])))
    return pm, wc, gm


def analyze_baseline(
    controller: BaselineController, params: BoucWenParams, *, delay: bool = False
) -> BaselineAnalysis:
    """Margins and stability of ``controller`` on the sampled nominal model (module docstring)."""
    if not isinstance(controller, BaselineController):
        raise InputError(
            f"controller must be a BaselineController, got {type(controller).__name__}"
        )
    dt = controller.dt
    cnum, cden = controller.transfer()
    lo, hi = slope_range(params)
    radii = []
    for slope in (params.alpha, lo, hi):
        pnum, pden = sampled_plant(params, dt, slope=slope, delay=delay)
        radii.append(_radius(cnum, cden, pnum, pden))
    pnum, pden = sampled_plant(params, dt, slope=params.alpha, delay=delay)
    pm, wc, gm = _margins(cnum, cden, pnum, pden, dt)
    gains = [params.a3 - params.a1 * s for s in (lo, hi)]
    grange = max(gains) / min(gains) if min(gains) > 0 else math.inf
    return BaselineAnalysis(
        stable=bool(max(radii) < 1.0),
        spectral_radius=radii[0],
        worst_radius=max(radii),
        phase_margin=pm,
        crossover=wc,
        gain_margin=gm,
        gain_range=float(grange),
        delay=bool(delay),
    )


def _shape(kind: str, wc: float, dt: float) -> BaselineController:
    """The controller of the rule at crossover ``wc`` with ``Kp = 1``."""
    ti = 4.0 / wc
    if kind == "pid":
        td = 1.0 / wc
        return BaselineController(1.0, 1.0 / ti, kd=td, tf=td / 10.0, dt=dt)
    return BaselineController(1.0, 1.0 / ti, dt=dt)


def _grid_phases(kind: str, w: np.ndarray, dt: float, pnum, pden) -> np.ndarray:
    """The rule's loop phase (Kp = 1) at every crossover candidate of ``w`` at once.

    ``C(z) = 1 + Ki dt z/(z - 1) [+ Kd/(Tf + dt) (z - 1)/(z - Tf/(Tf + dt))]`` with the
    rule's ``Ki = wc/4`` (and ``Kd = 1/wc``, ``Tf = Kd/10``) at ``wc = w``: the transfer of
    :func:`_shape` (:meth:`BaselineController.transfer`), evaluated in one pass.
    """
    z = np.exp(1j * w * dt)
    C = 1.0 + (w / 4.0) * dt * z / (z - 1.0)
    if kind == "pid":
        kd = 1.0 / w
        tf = kd / 10.0
        C = C + kd / (tf + dt) * (z - 1.0) / (z - tf / (tf + dt))
    return np.unwrap(np.angle(C * _response(pnum, pden, z)))


def _phase(kind, wc, dt, pnum, pden) -> tuple[float, float]:
    cnum, cden = _shape(kind, wc, dt).transfer()
    z = np.exp(1j * wc * dt)
    L = _response(cnum, cden, z) * _response(pnum, pden, z)
    return float(np.angle(L)), float(abs(L))


def tune_baseline(
    params: BoucWenParams,
    dt: float,
    *,
    kind: str = "pi",
    phase_margin: float = 60.0,
    delay: bool = False,
    u_limits: Any = None,
    feedforward: Any = None,
) -> BaselineController:
    """A PI or PID by the phase-margin rule of the module docstring.

    Parameters
    ----------
    params : BoucWenParams
        The stage's nominal (identified) model.
    dt : float
        Sample time (s).
    kind : {"pi", "pid"}
        The feedback part (a feedforward is added with ``feedforward``).
    phase_margin : float
        Target phase margin (deg), in :data:`PHASE_MARGIN`.
    delay : bool
        Tune for a one-sample computation delay.
    u_limits, feedforward
        As for :class:`BaselineController`.

    Raises
    ------
    GainError
        No crossover meets the target below the Nyquist frequency.
    """
    if kind not in ("pi", "pid"):
        raise InputError(f"kind must be 'pi' or 'pid', got {kind!r}")
    pm = real(phase_margin, "phase_margin (deg)", within=PHASE_MARGIN)
    pnum, pden = sampled_plant(params, dt, slope=params.alpha, delay=delay)
    target = math.radians(pm - 180.0)
    w = np.geomspace(1e-2 / dt, math.pi / dt * 0.999, _GRID)
    phases = _grid_phases(kind, w, dt, pnum, pden)
    below = np.flatnonzero(phases < target)
    if below.size == 0 or below[0] == 0:
        raise GainError(
            f"no crossover below the Nyquist frequency gives a {pm:g} deg phase margin for a "
            f"{kind.upper()} on this model at dt = {dt:g} s"
        )
    i = int(below[0])
    lo, hi = float(w[i - 1]), float(w[i])
    for _ in range(100):
        mid = math.sqrt(lo * hi)
        ph = _phase(kind, mid, dt, pnum, pden)[0]
        ph += 2 * math.pi * round((phases[i - 1] - ph) / (2 * math.pi))
        lo, hi = (mid, hi) if ph > target else (lo, mid)
    wc = math.sqrt(lo * hi)
    shape = _shape(kind, wc, dt)
    kp = 1.0 / _phase(kind, wc, dt, pnum, pden)[1]
    rule = TUNING_RULE.format(pm=pm, pid=", Td = 1/wc, Tf = Td/10" if kind == "pid" else "")
    return BaselineController(
        kp,
        kp * shape.ki,
        kd=kp * shape.kd,
        tf=shape.tf,
        dt=dt,
        u_limits=u_limits,
        feedforward=feedforward,
        tuning={"rule": rule, "phase_margin_deg": pm, "crossover_rad_s": wc, "delay": bool(delay)},
    )


def _reference_range(reference: Any) -> tuple[float, float]:
    period = reference.period
    t = np.linspace(0.0, period if period is not None else 2.0, 2001)
    if period is None and getattr(reference, "settles_at", None) is not None:
        t = np.linspace(0.0, max(1.0, 2.0 * reference.settles_at), 2001)
    xd = np.asarray(reference.evaluate(t)[0], dtype=float)
    return float(xd.min()), float(xd.max())


def make_baseline(
    params: BoucWenParams,
    dt: float,
    kind: str,
    *,
    reference: Any = None,
    gains: Any = None,
    phase_margin: float = 60.0,
    delay: bool = False,
    u_limits: Any = None,
    allow_unbounded: bool = False,
) -> BaselineController:
    """The baseline ``kind`` (:data:`~bwdesign.control.baselines.BASELINE_KINDS`) for a stage.

    Parameters
    ----------
    params : BoucWenParams
        The nominal model: the tuning's, the inverse Bouc–Wen feedforward's and the one
        whose quasi-static record the Prandtl–Ishlinskii operator is fitted to
        (:func:`bwdesign.identify.prandtl.model_record` over the reference's range,
        10 play operators).
    dt : float
    kind : str
    reference : Reference, optional
        Needed by ``"pi-piff"`` (the range the operator is fitted over).
    gains : sequence, optional
        Explicit ``(kp, ki)`` or ``(kp, ki, kd, tf)``; default :func:`tune_baseline`.
    phase_margin, delay, u_limits
        As for :func:`tune_baseline`.
    """
    from ..identify.prandtl import fit_prandtl_ishlinskii, model_record
    from .baselines import BASELINE_KINDS, InverseBoucWenFeedforward, PrandtlFeedforward

    if kind not in BASELINE_KINDS:
        raise InputError(f"baseline kind must be one of {', '.join(BASELINE_KINDS)}, got {kind!r}")
    ff = None
    if kind == "pi-bwff":
        ff = InverseBoucWenFeedforward(params, allow_unbounded=allow_unbounded)
    elif kind == "pi-piff":
        if reference is None:
            raise InputError("the pi-piff baseline needs the reference (its fitting range)")
        fit = fit_prandtl_ishlinskii(model_record(params, _reference_range(reference)))
        ff = PrandtlFeedforward(fit.operator, params.a1, params.a2)
    feedback = "pid" if kind == "pid" else "pi"
    if gains is None:
        return tune_baseline(
            params,
            dt,
            kind=feedback,
            phase_margin=phase_margin,
            delay=delay,
            u_limits=u_limits,
            feedforward=ff,
        )
    try:
        g = [float(v) for v in gains]
    except (TypeError, ValueError):
        raise GainError(
            f"baseline gains must be numbers (kp, ki[, kd, tf]), got {gains!r}"
        ) from None
    if len(g) not in (2, 4) or (len(g) == 4) != (kind == "pid"):
        want = "kp, ki, kd, tf" if kind == "pid" else "kp, ki"
        raise GainError(f"the {kind} baseline takes gains {want}, got {len(g)} value(s)")
    kd, tf = (g[2], g[3]) if len(g) == 4 else (0.0, None)
    return BaselineController(
        g[0], g[1], kd=kd, tf=tf, dt=dt, u_limits=u_limits, feedforward=ff, tuning=None
    )
