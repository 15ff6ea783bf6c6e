"""Digital tuning: observer and controller poles chosen for the sample rate."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..control.analysis import LoopAnalysis, analyze_loop
from ..control.controllers import TuningWarning, make_controller
from ..control.loop import ClosedLoop
from ..control.systems import LoopSystems, loop_systems, stability
from ..errors import ConfigError, InputError
from ..memo import Memo
from ..model.params import BoucWenParams
from ..model.plant import check_dt
from ..model.uncertainty import UncertaintyBox
from ..observers.gains import check_gains, gains_for_observer
from ..observers.spec import ObserverSpec
from ..validate import NONNEGATIVE, POSITIVE, Range, integer, real

__all__ = [
    "observer_gains",
    "digital_tuning",
    "stage_tuning",
    "DigitalTuning",
    "MarginRequirements",
]


def observer_gains(params: BoucWenParams, poles: Any) -> np.ndarray:
    """Continuous observer gains placing the poles of ``A0 - l C`` (eq. 5).

    The characteristic polynomial of ``A0 - l C`` is
    ``s^3 + (l1 + a2) s^2 + (l1 a2 + a1 + l2) s - l3 a1``; matching it to the
    requested poles gives ``l`` in closed form.

    Parameters
    ----------
    params : BoucWenParams
    poles : array_like, shape (3,)
        Self-conjugate set with negative real parts (1/s).

    Returns
    -------
    ndarray, shape (3,)
        (l1 1/s, l2 1/s^2, l3 1/s).

    Examples
    --------
    >>> from bwdesign import preset
    >>> l = observer_gains(preset("paper_experiment"), [-1000, -1000, -1000])
    >>> [round(v) for v in l]
    [2286, 1208283, -6257]
    """
    poles = np.asarray(poles, dtype=complex)
    if poles.shape != (3,) or not np.all(np.isfinite(poles)) or np.any(poles.real >= 0):
        raise InputError(
            f"observer poles must be three values with negative real parts, got {poles}"
        )
    c = np.poly(poles)
    if np.max(np.abs(c.imag)) > 1e-9 * np.max(np.abs(c)):
        raise InputError("observer poles must be a self-conjugate set")
    c = c.real
    l1 = c[1] - params.a2
    l2 = c[2] - params.a1 - l1 * params.a2
    l3 = -c[3] / params.a1
    return np.array([l1, l2, l3])


@dataclass(frozen=True)
class DigitalTuning:
    """A tuning of the sampled tracking loop with its verified margins.

    Attributes
    ----------
    lambda1, lambda2 : float
        Error poles of the discrete form of eq. (12) (1/s).
    integral_rate : float or None
        Integral action (1/s).
    gains : tuple of 3 floats
        Continuous observer gains (l1, l2, l3) (pole-matched to the sample rate).
    observer_bandwidth : float
        The observer's triple pole (rad/s).
    dt : float
        Sample time (s).
    form : str
        ``"discrete"``.
    delay : bool
        Whether the margins include a one-sample computation delay.
    mismatch : dict
        The relative parameter errors the margins were checked against.
    nominal : LoopAnalysis
        The loop with the exact model.
    worst_gain_margin_db, worst_phase_margin, worst_delay_margin : float
        Worst case over nominal and the mismatch corners (dB, deg, s).
    requirements : dict
        ``min_gain_margin_db``, ``min_phase_margin``, ``min_delay_margin`` (s).
    met : bool
        Whether the worst case meets the requirements.
    candidates : list of dict
        Every (observer bandwidth, lambda) tried, with its worst-case margins
        (``verified``: confirmed by :func:`analyze_loop`, else a frequency-response screen).
    reasoning : str
        How the numbers were chosen, in words.
    """

    lambda1: float
    lambda2: float
    integral_rate: float | None
    gains: tuple[float, float, float]
    observer_bandwidth: float
    dt: float
    form: str
    delay: bool
    mismatch: dict
    nominal: LoopAnalysis
    worst_gain_margin_db: float
    worst_phase_margin: float
    worst_delay_margin: float
    requirements: dict
    met: bool
    candidates: list
    reasoning: str

    def observer_gains_for(self, observer: str = "phso") -> tuple[float, ...]:
        """The continuous gains of this tuning for ``observer`` ("phso", "eso" or "phdo").

        The PHSO and the ESO use ``gains``. The disturbance observer (PHDO) gets
        ``(l1, l2, 0, l3)``: its observable part ``(x1, x2, x3 + d)`` has the same
        poles as the tuned observer (so the loop analysed here is its loop too),
        the whole correction of the lumped state goes to ``d`` and the hysteresis
        copy runs on the model alone (``l3 = 0``, under which its lumped error
        converges for every input; see :class:`bwdesign.DisturbanceHysteresisObserver`).
        """
        return gains_for_observer(observer, self.gains)

    def controller_kwargs(self, *, observer: str = "phso") -> dict[str, Any]:
        """The tuning as flat keywords: ``gains`` (for ``observer``), ``lambda1``, ``lambda2``,
        ``form``, ``integral_rate`` (the law's are :func:`~bwdesign.make_controller`'s).

        A loop is built from a tuning by
        :meth:`ClosedLoop.from_config(config, law=tuning) <bwdesign.ClosedLoop.from_config>`.
        """
        return {
            "gains": self.observer_gains_for(observer),
            "lambda1": self.lambda1,
            "lambda2": self.lambda2,
            "form": self.form,
            "integral_rate": self.integral_rate,
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            "lambda1": self.lambda1,
            "lambda2": self.lambda2,
            "integral_rate": self.integral_rate,
            "gains": list(self.gains),
            "observer_bandwidth": self.observer_bandwidth,
            "dt": self.dt,
            "form": self.form,
            "delay": self.delay,
            "mismatch": self.mismatch,
            "nominal": self.nominal.to_dict(),
            "worst_gain_margin_db": self.worst_gain_margin_db,
            "worst_phase_margin_deg": self.worst_phase_margin,
            "worst_delay_margin_s": self.worst_delay_margin,
            "requirements": self.requirements,
            "met": self.met,
            "candidates": self.candidates,
            "reasoning": self.reasoning,
        }


def _mismatch_plants(
    params: BoucWenParams, mismatch: float, box: UncertaintyBox | None
) -> tuple[list[BoucWenParams | None], dict[str, float]]:
    """The plants the margins are checked on (None = the model) and their relative errors."""
    if box is None:
        truths: list[BoucWenParams | None] = [None]
        if mismatch > 0:
            truths += [
                params.replace(a1=params.a1 * (1 + d1), a3=params.a3 * (1 + d3))
                for d1 in (-mismatch, mismatch)
                for d3 in (-mismatch, mismatch)
            ]
        return truths, {"a1": mismatch, "a3": mismatch}
    box.check(params, bounded=False)
    linear = ("a1", "a2", "a3")
    checked = {k: box.half_width(k, params) / abs(getattr(params, k)) for k in linear}
    seen = {tuple(getattr(params, k) for k in linear)}
    truths = [None]
    for v in box.vertices(params):
        key = tuple(getattr(v, k) for k in linear)
        if key not in seen:
            seen.add(key)
            truths.append(params.replace(**dict(zip(linear, key, strict=True))))
    return truths, {k: v for k, v in checked.items() if v > 0}


def _corners_text(checked: dict[str, float], n: int) -> str:
    if not checked:
        return "no mismatch corner"
    return ", ".join(f"{k} = (1 +- {v:.3g})" for k, v in checked.items()) + f" model ({n} corners)"


def _fast_margins(sy: LoopSystems, dt: float, w: np.ndarray) -> tuple[float, float, float] | None:
    """Worst-case screening margins (GM dB, PM deg, DM s) of a sampled loop from a grid.

    ``None`` when the closed loop is unstable. The loop broken at the plant input is
    ``L = -c (zI - A_ol)^-1 b`` with ``A_in = b c`` (rank one) and ``A_ol = A_cl - A_in``;
    the gain-margin interval ends where ``k L`` meets -1 (``L`` on the negative real
    axis), the phase margin is taken at the ``|L| = 1`` crossing nearest -1. Crossings
    are interpolated linearly on ``w``: a screen, confirmed by :func:`analyze_loop`.
    """
    A_cl, A_in = sy.A_cl, sy.A_in
    if not stability(A_cl, dt)[0]:
        return None
    i, j = np.unravel_index(np.argmax(np.abs(A_in)), A_in.shape)
    b = A_in[:, j]
    c = A_in[i, :] / A_in[i, j]
    n = A_cl.shape[0]
    z = np.exp(1j * w * dt)
    M = z[:, None, None] * np.eye(n)[None] - (A_cl - A_in)[None]
    try:
        x = np.linalg.solve(M, np.broadcast_to(b.astype(complex), (len(w), n))[..., None])
    except np.linalg.LinAlgError:
        return None
    L = -(x[..., 0] @ c)
    im = L.imag
    ks = []
    for k in np.nonzero(np.signbit(im[:-1]) != np.signbit(im[1:]))[0]:
        t = im[k] / (im[k] - im[k + 1])
        re = L[k].real + t * (L[k + 1].real - L[k].real)
        if re < 0:
            ks.append(-1.0 / re)
    ks = np.array(ks)
    up = float(ks[ks > 1].min()) if np.any(ks > 1) else math.inf
    dn = float(ks[ks < 1].max()) if np.any(ks < 1) else 0.0
    gm = 20 * math.log10(min(up, 1.0 / dn if dn > 0 else math.inf))
    lm = np.log(np.abs(L))
    pm, wc = math.inf, math.nan
    for k in np.nonzero(np.signbit(lm[:-1]) != np.signbit(lm[1:]))[0]:
        t = lm[k] / (lm[k] - lm[k + 1])
        p = (np.angle(L[k] + t * (L[k + 1] - L[k]), deg=True) + 180.0) % 360.0
        p = p - 360.0 if p > 180.0 else p
        if abs(p) < abs(pm):
            pm, wc = float(p), float(w[k] + t * (w[k + 1] - w[k]))
    dm = math.inf if not math.isfinite(pm) else (math.radians(pm) / wc if pm > 0 else -math.inf)
    return gm, pm, dm


_RADII = (0.1, 0.16, 0.25, 0.4, 0.63, 1.0, 1.6)


@dataclass(frozen=True)
class MarginRequirements:
    """The worst-case margins a :func:`digital_tuning` must reach.

    Parameters
    ----------
    gain_db : float
        Gain margin (dB), >= 0.
    phase_deg : float
        Phase margin (deg), >= 0.
    delay_samples : float
        Delay margin in samples of ``dt``, >= 0. A zero requirement is no requirement.
    """

    gain_db: float = 6.0
    phase_deg: float = 45.0
    delay_samples: float = 1.0

    def __post_init__(self) -> None:
        for name, unit in (("gain_db", "dB"), ("phase_deg", "deg"), ("delay_samples", "")):
            value = real(getattr(self, name), f"margins.{name} {unit}".rstrip(), within=NONNEGATIVE)
            object.__setattr__(self, name, value)

    def as_dict(self, dt: float) -> dict[str, float]:
        """``min_gain_margin_db``, ``min_phase_margin`` (deg) and ``min_delay_margin`` (s)."""
        return {
            "min_gain_margin_db": float(self.gain_db),
            "min_phase_margin": float(self.phase_deg),
            "min_delay_margin": float(self.delay_samples) * dt,
        }


#: Observer bandwidth times dt: the poles ``-radius/dt`` stay inside the sampled loop's reach.
OBSERVER_RADIUS = Range(0.0, 2.0, lo_open=True, hi_open=True)
#: Relative model error the tuning designs for.
MISMATCH = Range(0.0, 0.5, hi_open=True)


def digital_tuning(
    params: BoucWenParams,
    dt: float,
    *,
    gains: Any = None,
    observer_radius: float | None = None,
    integral_ratio: float | None = 0.5,
    mismatch: float | None = None,
    uncertainty: UncertaintyBox | None = None,
    delay: bool = True,
    margins: MarginRequirements = MarginRequirements(),
    n_candidates: int = 9,
) -> DigitalTuning:
    """Choose the eq. (12) constants (and observer gains) for a loop sampled at ``dt``.

    Procedure:

    1. Observer: unless ``gains`` is given, a triple pole at
       ``omega_o = r / dt`` (discrete radius ``exp(-r)``). With
       ``observer_radius`` given, ``r`` is that value; by default ``r`` is
       searched over 0.1 ... 1.6 together with ``lambda``. The search matters
       for lightly damped stages: an observer much slower than the plant's
       resonance ``sqrt(a1)`` must move the resonant poles a long way with
       large gains, and the loop is then fragile (e.g. the 800 Hz, 5 % stack at
       20 kHz needs ``omega_o`` above the resonance); a slow, well damped stage
       prefers a moderate ``r`` (less sensor noise passes a slower observer).
    2. Law: the discrete form of eq. (12) (ZOH-exact pole placement, mid-sample
       feedforward) with ``lambda1 = lambda2 = lambda`` and, unless
       ``integral_ratio`` is None, integral action at
       ``integral_ratio * lambda``. Integral action is what lets the PHSO loop
       live with a static-gain (a1, a3) error that its hysteresis state cannot
       absorb.
    3. For each observer bandwidth, ``lambda`` is scanned over
       ``[omega_o/100, omega_o/2]``; each candidate's linear loop (with the
       one-sample delay if ``delay``) is screened at nominal and at the four
       corners ``a1, a3 = (1 +- mismatch) model`` (with ``uncertainty``: at
       every distinct ``(a1, a2, a3)`` corner of the box instead) from its
       frequency response.
       The best few are then analysed exactly (:func:`analyze_loop`). Among
       the candidates whose worst-case *robustness score*
       ``min(GM/GM_req, PM/PM_req, DM/DM_req)`` reaches 1, the slowest
       observer wins (it passes the least sensor noise), and within it the
       most robust lambda. If no candidate reaches a score of 1 the most
       robust one is reported and the result says so (``met=False``);
       nothing is relaxed.

    Parameters
    ----------
    params : BoucWenParams
        The stage model.
    dt : float
        Sample time (s).
    gains : array_like, shape (3,), optional
        Keep these observer gains instead of designing them.
    observer_radius : float, optional
        ``omega_o dt`` of the designed observer (dimensionless, in (0, 2));
        None (default) searches it.
    integral_ratio : float or None
        Integral pole as a fraction of ``lambda``; None for no integral action.
    mismatch : float, optional
        Relative a1, a3 error the margins must survive (default 0.02 = +-2 %).
    uncertainty : UncertaintyBox, optional
        Choose against this box instead of ``mismatch``: the margins must hold
        at every corner of its linear part ``(a1, a2, a3)`` (the hysteresis
        parameters do not enter the linear margins; :func:`bwdesign.certify_robust`
        covers them). Not together with ``mismatch``. Every half-width finite and
        every corner a valid model (:meth:`UncertaintyBox.check` with
        ``bounded=False``; ``ParameterError`` otherwise).
    delay : bool
        Include a one-sample computation delay (delay-compensated law).
    margins : MarginRequirements
        The worst-case gain, phase and delay margins required (default 6 dB, 45 deg,
        one sample).
    n_candidates : int
        Number of lambda values scanned per observer bandwidth.

    Returns
    -------
    DigitalTuning
        Kept for the process by its exact arguments: asked again, a copy of the kept
        answer comes back without computing it.
    """
    dt = check_dt(dt)
    if observer_radius is not None:
        observer_radius = real(observer_radius, "observer_radius", within=OBSERVER_RADIUS)
    mismatch = _checked_mismatch(mismatch, uncertainty)
    if integral_ratio is not None:
        integral_ratio = real(integral_ratio, "integral_ratio", within=POSITIVE)
    if not isinstance(margins, MarginRequirements):
        raise InputError(f"margins must be a MarginRequirements, got {margins!r}")
    n_candidates = integer(n_candidates, "n_candidates", within=Range(1, 10_000))
    args = (params, dt, gains, observer_radius, integral_ratio, mismatch, uncertainty, delay)
    return _MEMO.get((*args, margins, n_candidates), lambda: _tune(*args, margins, n_candidates))


#: :func:`digital_tuning`'s answers kept by their exact arguments, in this process: it is
#: a pure function of them (the report's parts, the robust design and the checks ask for
#: the same stage's tuning again). A copy goes out, so no caller changes another's.
_MEMO: Memo[DigitalTuning] = Memo(16)


def _tune(
    params: BoucWenParams,
    dt: float,
    gains: Any,
    observer_radius: float | None,
    integral_ratio: float | None,
    mismatch: float | None,
    uncertainty: UncertaintyBox | None,
    delay: bool,
    margins: MarginRequirements,
    n_candidates: int,
) -> DigitalTuning:
    """:func:`digital_tuning` on validated arguments."""
    observers = _observers(params, dt, gains, observer_radius)
    truths, checked = _mismatch_plants(params, mismatch, uncertainty)
    req = margins.as_dict(dt)
    law = _Law(dt, integral_ratio, delay)
    # 1. screen every (observer, lambda) from the frequency response
    cands = _screen(params, law, observers, truths, req, n_candidates)
    # 2. confirm the best few with the exact analysis (eigenvalue gain interval,
    #    python-control phase margin); the reported numbers are these
    row, nominal = _confirm_best(params, law, cands, truths, req)
    met = bool(row["stable"] and row["score"] >= 1.0)
    designed = (gains is None, observer_radius is None)
    scanned = (len(cands), n_candidates, _corners_text(checked, len(truths) - 1))
    return DigitalTuning(
        lambda1=row["lambda"],
        lambda2=row["lambda"],
        integral_rate=row["integral_rate"],
        gains=tuple(float(v) for v in row["gains"]),
        observer_bandwidth=float(row["observer_bandwidth"]),
        dt=dt,
        form="discrete",
        delay=bool(delay),
        mismatch=checked,
        nominal=nominal,
        worst_gain_margin_db=row["worst_gain_margin_db"],
        worst_phase_margin=row["worst_phase_margin_deg"],
        worst_delay_margin=row["worst_delay_margin_s"],
        requirements=req,
        met=met,
        candidates=cands,
        reasoning=_reasoning(params, law, row, designed, margins, scanned, met),
    )


def stage_tuning(config: Any, tuning: str) -> DigitalTuning | None:
    """The law a stage's loop runs: ``None`` for ``tuning="config"`` (its ``[observer]``
    gains and ``[controller]`` constants), :func:`digital_tuning` at its ``[sampling] dt``
    for ``"digital"``. What a caller of :func:`bwdesign.sim.sweep.spec_from_config` (the
    sweep, which simulates the gains it is given) calls first.

    Raises
    ------
    InputError
        ``tuning`` is neither.
    ConfigError
        ``"digital"`` for a stage without ``[sampling] dt``.
    """
    if tuning not in ("config", "digital"):
        raise InputError(f"tuning must be 'config' or 'digital', got {tuning!r}")
    if tuning == "config":
        return None
    if config.dt is None:
        raise ConfigError(f"{config.source or 'config'}: the digital tuning needs [sampling] dt")
    return digital_tuning(config.plant, config.dt)


def _checked_mismatch(mismatch: float | None, uncertainty: UncertaintyBox | None) -> float:
    """The relative a1, a3 error to tune against (0 with a box, whose corners are used)."""
    if uncertainty is not None and mismatch is not None:
        raise InputError("give mismatch or uncertainty, not both")
    if uncertainty is not None and not isinstance(uncertainty, UncertaintyBox):
        raise InputError(f"uncertainty must be an UncertaintyBox, got {uncertainty!r}")
    if mismatch is None:
        mismatch = 0.0 if uncertainty is not None else 0.02
    return real(mismatch, "mismatch (relative error)", within=MISMATCH)


@dataclass(frozen=True)
class _Law:
    """The discrete eq. (12) law every candidate runs, but for its ``lambda``."""

    dt: float
    integral_ratio: float | None
    delay: bool

    def integral_rate(self, lam: float) -> float | None:
        return None if self.integral_ratio is None else self.integral_ratio * lam

    def loop(self, params: BoucWenParams, lam: float, gains: Any) -> ClosedLoop:
        """The candidate's loop: the PHSO with ``gains``, this law with ``lambda = lam``."""
        ir = self.integral_rate(lam)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", TuningWarning)
            law = make_controller(params, lam, lam, form="discrete", dt=self.dt, integral_rate=ir)
        spec = ObserverSpec.of("phso", gains)
        # the linear analysis holds x3: the hysteresis class does not enter the margins
        return ClosedLoop(params, spec, law, dt=self.dt, delay=self.delay, allow_unbounded=True)


def _score(req: dict[str, float], gm: float, pm: float, dm: float) -> float:
    """The robustness score ``min(GM/GM_req, PM/PM_req, DM/DM_req)`` (a zero requirement: inf)."""
    return min(
        gm / req["min_gain_margin_db"] if req["min_gain_margin_db"] > 0 else math.inf,
        pm / req["min_phase_margin"] if req["min_phase_margin"] > 0 else math.inf,
        dm / req["min_delay_margin"] if req["min_delay_margin"] > 0 else math.inf,
    )


def _observers(
    params: BoucWenParams, dt: float, gains: Any, observer_radius: float | None
) -> list[tuple[float, np.ndarray]]:
    """The observers to try: ``(omega_o, gains)``, designed or the given gains."""
    if gains is None:
        radii = _RADII if observer_radius is None else (float(observer_radius),)
        observers = []
        for r in radii:
            om = r / dt
            try:
                observers.append((om, observer_gains(params, [-om] * 3)))
            except InputError:  # pragma: no cover - a triple real pole is always valid
                continue
        return observers
    l = check_gains(params, gains)  # the loop of every candidate needs Hurwitz gains
    ev = np.linalg.eigvals(
        np.array(
            [
                [-l[0], 1.0, 0.0],
                [-(params.a1 + l[1]), -params.a2, -params.a1],
                [-l[2], 0.0, 0.0],
            ]
        )
    )
    return [(float(np.min(np.abs(ev))), l)]


def _screen(
    params: BoucWenParams,
    law: _Law,
    observers: list[tuple[float, np.ndarray]],
    truths: list[BoucWenParams | None],
    req: dict[str, float],
    n_candidates: int,
) -> list[dict[str, Any]]:
    """Every (observer, lambda) with its worst-case margins screened from the frequency response."""
    dt = law.dt
    cands: list[dict[str, Any]] = []
    for om, l in observers:
        w = np.geomspace(om / 1e4, math.pi / dt, 500)
        for lam in np.geomspace(om / 100.0, om / 2.0, int(n_candidates)):
            lam = float(lam)
            worst = [math.inf, math.inf, math.inf]
            stable = True
            pruned = False
            try:
                loop = law.loop(params, lam, l)
            except InputError:
                loop, stable = None, False
            for tp in truths if loop is not None else ():
                try:
                    sy = loop_systems(loop, true_params=tp, lti=False)
                    m = _fast_margins(sy, dt, w)
                except (InputError, np.linalg.LinAlgError, ValueError):
                    m = None
                if m is None:
                    stable = False
                    break
                worst = [min(a, b) for a, b in zip(worst, m, strict=True)]
                sc = _score(req, *worst)
                if cands and sc < 1.0 and sc < max(c["score"] for c in cands) - 0.5:
                    pruned = True  # the worst case can only fall further: not a contender
                    break
            cands.append(
                {
                    "observer_bandwidth": float(om),
                    "gains": tuple(float(v) for v in l),
                    "lambda": lam,
                    "integral_rate": law.integral_rate(lam),
                    "stable": stable,
                    "worst_gain_margin_db": worst[0] if stable else -math.inf,
                    "worst_phase_margin_deg": worst[1] if stable else -math.inf,
                    "worst_delay_margin_s": worst[2] if stable else -math.inf,
                    "score": _score(req, *worst) if stable else -math.inf,
                    "verified": False,
                    "pruned": pruned,
                }
            )
    return cands


def _verify(
    params: BoucWenParams,
    law: _Law,
    c: dict[str, Any],
    truths: list[BoucWenParams | None],
    req: dict[str, float],
) -> LoopAnalysis:
    """Confirm candidate ``c`` with :func:`analyze_loop` (updates ``c``); its nominal analysis."""
    worst = [math.inf, math.inf, math.inf]
    stable = True
    nominal = None
    loop = law.loop(params, c["lambda"], c["gains"])
    for tp in truths:
        a = analyze_loop(loop, true_params=tp)
        if nominal is None:
            nominal = a
        stable &= a.stable
        pm = a.phase_margin if math.isfinite(a.phase_margin) else math.inf
        dm = a.delay_margin if math.isfinite(a.delay_margin) else math.inf
        m = (a.gain_margin_db, pm, dm) if a.stable else (-math.inf,) * 3
        worst = [min(x, y) for x, y in zip(worst, m, strict=True)]
    c.update(
        stable=stable,
        worst_gain_margin_db=worst[0],
        worst_phase_margin_deg=worst[1],
        worst_delay_margin_s=worst[2],
        score=_score(req, *worst) if stable else -math.inf,
        verified=True,
    )
    return nominal


def _confirm_best(
    params: BoucWenParams,
    law: _Law,
    cands: list[dict[str, Any]],
    truths: list[BoucWenParams | None],
    req: dict[str, float],
) -> tuple[dict[str, Any], LoopAnalysis]:
    """The best of the three best-screened candidates after :func:`_verify`, with its analysis."""
    order = sorted(range(len(cands)), key=lambda i: _rank(cands[i]), reverse=True)
    best = None
    for i in order[:3]:
        nominal = _verify(params, law, cands[i], truths, req)
        if best is None or _rank(cands[i]) > _rank(best[0]):
            best = (cands[i], nominal)
    return best


def _rank(c: dict) -> tuple[bool, float, float]:
    # candidates meeting the requirements first; among them the slowest
    # observer (it passes the least sensor noise), then the most robust
    meets = c["stable"] and c["score"] >= 1.0
    return (meets, -c["observer_bandwidth"] if meets else 0.0, c["score"])


def _reasoning(
    params: BoucWenParams,
    law: _Law,
    row: dict[str, Any],
    designed: tuple[bool, bool],
    margins: MarginRequirements,
    scanned: tuple[int, int, str],
    met: bool,
) -> str:
    """How the tuning was chosen, in words.

    ``designed``: (the observer was designed, its radius searched); ``scanned``: (number of
    candidates, lambda values per observer, the corners checked).
    """
    dt, lam, omega_o, l = law.dt, row["lambda"], row["observer_bandwidth"], row["gains"]
    n_screened, n_candidates, corners = scanned
    if designed[0]:
        r = omega_o * dt
        obs_note = (
            f"observer: triple pole at {omega_o:.4g} rad/s (discrete radius exp(-{r:.3g}) = "
            f"{math.exp(-r):.3f} at dt = {dt:g} s"
            + (
                f", omega_o dt searched over {', '.join(f'{v:g}' for v in _RADII)}"
                if designed[1]
                else ""
            )
            + f"; plant resonance sqrt(a1) = {math.sqrt(params.a1):.4g} rad/s), "
            f"gains l = ({l[0]:.6g}, {l[1]:.6g}, {l[2]:.6g})"
        )
    else:
        obs_note = f"observer: the given gains l = ({l[0]:g}, {l[1]:g}, {l[2]:g})"
    if met:
        verdict = "requirements met"
    else:
        verdict = (
            "requirements NOT met by any candidate: the best tuning found falls short; do not "
            "use it as is (a faster sample rate against the plant resonance, a smaller mismatch "
            "or looser requirements are needed)"
        )
        if not row["stable"]:
            verdict = (
                "no candidate gives a loop stable at nominal and at every mismatch corner (the "
                f"resonance sqrt(a1) dt = {math.sqrt(params.a1) * dt:.2g} rad per sample, "
                f"Nyquist is pi); {verdict}"
            )
    ratio = law.integral_ratio
    return "; ".join(
        [
            obs_note,
            "law: discrete form of eq. (12) (error poles placed at exp(-lambda dt) on the exact "
            "ZOH model, feedforward at mid-sample)"
            + ("" if ratio is None else f" with integral action at {ratio:g} lambda"),
            f"lambda = lambda1 = lambda2 scanned over {int(n_candidates)} values in "
            f"[omega_o/100, omega_o/2] for each observer bandwidth ({n_screened} candidates, "
            "screened from the frequency response, the best 3 confirmed by the exact analysis)",
            f"each checked at nominal and at {corners}"
            + (" with a one-sample computation delay" if law.delay else ""),
            (
                "chosen: the slowest observer (least sensor noise) with a candidate meeting "
                "the requirements, and its lambda with the best worst-case score"
                if met
                else "chosen: the largest worst-case score"
            )
            + f" min(GM/{margins.gain_db:g} dB, PM/{margins.phase_deg:g} deg, DM/"
            f"{margins.delay_samples:g} sample), lambda = {lam:.4g} 1/s: "
            f"GM {row['worst_gain_margin_db']:.3g} dB, "
            f"PM {row['worst_phase_margin_deg']:.3g} deg, delay margin "
            f"{row['worst_delay_margin_s'] / dt:.3g} samples (worst case)",
            verdict,
        ]
    )
