"""Poles and margins of the linear tracking loop, and model-mismatch sweeps."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams
from .loop import ClosedLoop
from .systems import LoopSystems, gain_interval, loop_systems, stability

__all__ = ["LoopAnalysis", "MismatchSweep", "analyze_loop", "mismatch_sweep", "stability_interval"]


@dataclass(frozen=True)
class LoopAnalysis:
    """Poles and margins of the linear tracking loop.

    Attributes
    ----------
    lambda1, lambda2 : float
        Eq. (12) constants (1/s).
    gains : tuple of float or None
        Continuous observer gains (None for ``estimator="state"``).
    dt : float or None
        Sample time (s); None for the continuous loop.
    integral_rate : float or None
        Integral action (1/s) of the discrete form.
    form, estimator : str
    delay : bool
        One-sample computation delay included.
    poles : ndarray (complex)
        Closed-loop eigenvalues: s-plane (1/s) when continuous, z-plane when sampled.
    poles_s : ndarray (complex)
        Equivalent continuous poles (``log(z)/dt`` when sampled), 1/s.
    stable : bool
    spectral_radius : float or None
        ``max |z|`` (sampled loops).
    max_real_part : float
        max Re of ``poles_s`` (1/s); for a stable loop, minus the slowest decay rate.
    gain_margin : (float, float)
        Loop-gain interval ``(k_min, k_max)`` keeping the loop stable (1 inside).
    gain_margin_db : float
        ``20 log10(min(k_max, 1/k_min))`` (dB).
    phase_margin : float
        Smallest phase margin over the gain crossovers (deg); nan when none.
    crossover : float
        Gain-crossover frequency of that margin (rad/s).
    delay_margin : float
        ``phase_margin (rad) / crossover`` (s); nan without a positive phase margin.
    true_params : dict or None
        The true plant when it differs from the model.
    """

    lambda1: float
    lambda2: float
    gains: tuple[float, float, float] | None
    dt: float | None
    integral_rate: float | None
    form: str
    estimator: str
    delay: bool
    poles: np.ndarray
    poles_s: np.ndarray
    stable: bool
    spectral_radius: float | None
    max_real_part: float
    gain_margin: tuple[float, float]
    gain_margin_db: float
    phase_margin: float
    crossover: float
    delay_margin: float
    true_params: dict | None = None
    systems: LoopSystems | None = field(default=None, repr=False, compare=False)

    @property
    def slowest_decay_rate(self) -> float:
        """``-max Re(poles_s)`` (1/s): the rate of the slowest mode."""
        return -self.max_real_part

    def tracking_gain(self, frequency: float) -> complex:
        """Complex gain from a sinusoidal reference to the tracking error at ``frequency`` (Hz).

        For ``x_d = exp(j w t)`` the law receives ``(x_d, j w x_d, -w^2 x_d)``; the
        value is ``E/X_d`` of the linear loop (0 for a perfect feedforward).
        """
        if self.systems is None:
            raise InputError("this analysis was built without its systems")
        sy = self.systems
        w = 2 * math.pi * float(frequency)
        r = complex(sy.ref_gain @ np.array([1.0, 1j * w, -(w**2)]))
        n = sy.A_cl.shape[0]
        rhs = sy.B_ff * r
        if sy.dt is None:
            lam = 1j * w
        else:
            lam = complex(np.exp(1j * w * sy.dt))
            rhs = rhs - sy.dt * sy.B_int
            if sy.ref_advance:
                rhs = rhs * lam
        x = np.linalg.solve(lam * np.eye(n) - sy.A_cl, rhs)
        return complex(x[0] - 1.0)

    def to_dict(self) -> dict[str, Any]:
        def cl(z):
            return [[float(v.real), float(v.imag)] for v in z]

        return {
            "lambda1": self.lambda1,
            "lambda2": self.lambda2,
            "gains": list(self.gains) if self.gains else None,
            "dt": self.dt,
            "integral_rate": self.integral_rate,
            "form": self.form,
            "estimator": self.estimator,
            "delay": self.delay,
            "poles": cl(self.poles),
            "poles_s": cl(self.poles_s),
            "stable": self.stable,
            "spectral_radius": self.spectral_radius,
            "max_real_part": self.max_real_part,
            "gain_margin": list(self.gain_margin),
            "gain_margin_db": self.gain_margin_db,
            "phase_margin_deg": self.phase_margin,
            "crossover_rad_s": self.crossover,
            "delay_margin_s": self.delay_margin,
            "true_params": self.true_params,
        }


def analyze_loop(
    loop: ClosedLoop,
    *,
    true_params: BoucWenParams | None = None,
    estimator: str = "observer",
) -> LoopAnalysis:
    """Closed-loop poles and stability margins of the linear tracking loop.

    Parameters
    ----------
    loop : ClosedLoop
        The loop analysed: its ``model`` (observer and law), its observer's continuous
        gains (PHSO or ESO; mapped to the discrete correction by
        :func:`bwdesign.observers.discrete_gains` when the loop has a ``dt``), its
        eq. (12) law (continuous, or
        :class:`~bwdesign.control.controllers.DiscreteTrackingController` with its
        integral action), its ``dt`` (``None``: the continuous loop; else the sampled
        loop, exact ZOH plant, discrete observer, law evaluated at the samples and held)
        and its one-sample delay (with ``compensate_delay`` the law uses the one-step
        prediction and the reference at ``t_{k+1}``, as :func:`bwdesign.sim.simulate`
        does). Input limits and estimate clipping are outside the linear analysis.
    true_params : BoucWenParams, optional
        The plant's true parameters (model mismatch).
    estimator : {"observer", "state"}
        Output feedback through the observer, or true-state feedback (comparison; the
        loop's observer is then not used).

    Returns
    -------
    LoopAnalysis

    Examples
    --------
    >>> from bwdesign import ClosedLoop, ObserverSpec, make_controller, preset
    >>> p = preset("paper_experiment")
    >>> law = make_controller(p, 1.0, 2.0)
    >>> loop = ClosedLoop(p, ObserverSpec.of("phso", (8, 64, -512)), law, dt=2e-4)
    >>> a = analyze_loop(loop)
    >>> a.stable, round(a.slowest_decay_rate, 2)
    (True, 0.1)
    """
    sy = loop_systems(loop, true_params=true_params, estimator=estimator)
    dt = sy.dt
    poles = np.linalg.eigvals(sy.A_cl)
    if dt is None:
        poles_s = poles
        rho = None
    else:
        with np.errstate(divide="ignore"):
            poles_s = np.log(poles.astype(complex)) / dt
        rho = float(np.max(np.abs(poles)))
    stable, _ = stability(sy.A_cl, dt)
    maxre = float(np.max(poles_s.real))

    gm = gain_interval(sy.with_loop_gain, dt)
    if stable and gm[0] >= 0:
        up = gm[1]
        down = 1.0 / gm[0] if gm[0] > 0 else math.inf
        gm_db = 20 * math.log10(min(up, down))
    else:
        gm_db = math.nan
    pm, wc = _phase_margin(sy.loop, dt)
    ok_dm = math.isfinite(pm) and pm > 0 and math.isfinite(wc) and wc > 0
    dm = math.radians(pm) / wc if ok_dm else math.nan
    ctrl = loop.controller
    return LoopAnalysis(
        lambda1=float(ctrl.lambda1),
        lambda2=float(ctrl.lambda2),
        gains=None if estimator == "state" else tuple(float(v) for v in loop.observer.gains),
        dt=dt,
        integral_rate=ctrl.integral_rate,
        form=ctrl.form,
        estimator=estimator,
        delay=loop.delay,
        poles=poles,
        poles_s=poles_s,
        stable=bool(stable),
        spectral_radius=rho,
        max_real_part=maxre,
        gain_margin=gm,
        gain_margin_db=gm_db,
        phase_margin=pm,
        crossover=wc,
        delay_margin=dm,
        true_params=None if true_params is None else true_params.to_dict(),
        systems=sy,
    )


@dataclass(frozen=True)
class MismatchSweep:
    """Loop stability and margins against a relative error in one plant parameter.

    ``true = (1 + delta) * model`` for the parameter named ``parameter``.

    Attributes
    ----------
    parameter : str
    deltas : ndarray
        Relative errors (dimensionless).
    stable : ndarray of bool
    spectral_radius : ndarray
        ``max |z|`` (sampled) or nan (continuous).
    max_real_part : ndarray
        max Re of the equivalent continuous poles (1/s).
    gain_margin_db, phase_margin : ndarray
        dB and deg (nan where unstable or undefined).
    interval : (float, float)
        Stability interval of delta around 0 found by bisection (within the
        search bounds ``[-0.99, 10]``; an end at a bound means "at least").
    """

    parameter: str
    deltas: np.ndarray
    stable: np.ndarray
    spectral_radius: np.ndarray
    max_real_part: np.ndarray
    gain_margin_db: np.ndarray
    phase_margin: np.ndarray
    interval: tuple[float, float]

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameter": self.parameter,
            "deltas": self.deltas.tolist(),
            "stable": self.stable.tolist(),
            "spectral_radius": self.spectral_radius.tolist(),
            "max_real_part": self.max_real_part.tolist(),
            "gain_margin_db": self.gain_margin_db.tolist(),
            "phase_margin_deg": self.phase_margin.tolist(),
            "stability_interval": list(self.interval),
        }


def _phase_margin(loop: Any, dt: float | None) -> tuple[float, float]:
    """``(phase margin deg, crossover rad/s)`` nearest -1 of the broken loop (nan when none)."""
    pm, wc = math.nan, math.nan
    import control

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # python-control's 'poly'->'frd' note
            # 'frd' for sampled loops (python-control's 'poly' step fails on them and falls
            # back anyway); 'best' for continuous loops ('frd' needs a grid there)
            if dt:
                pms, wgc = frd_phase_margins(loop)
            else:
                _, pms, _, _, wgc, _ = control.stability_margins(loop, returnall=True)
        pms = np.atleast_1d(np.asarray(pms, dtype=float))
        wgc = np.atleast_1d(np.asarray(wgc, dtype=float))
        ok = np.isfinite(pms) & np.isfinite(wgc)
        if np.any(ok):
            i = int(np.argmin(np.abs(np.where(ok, pms, np.inf))))
            pm, wc = float(pms[i]), float(wgc[i])
    except Exception:  # python-control may fail on degenerate loops; margins stay nan
        pass
    return pm, wc


def frd_phase_margins(loop: Any) -> tuple[np.ndarray, np.ndarray]:
    """Every phase margin (deg) and its gain crossover (rad/s) of a sampled loop, as
    ``control.stability_margins(loop, returnall=True, method="frd")`` computes them.

    The same steps on the same numbers (the loop's transfer function, python-control's
    default frequency grid below Nyquist, its smoothed frequency response, a root of
    ``|L| - 1`` between each pair of grid points where it changes sign), so the margins
    are python-control's to the bit (tested), without the gain and stability margins it
    computes beside them, which the analysis does not read (two thirds of its time).
    Where python-control's internals are not there (another version), it is called.
    """
    import control
    import scipy.optimize

    try:
        from control import frdata, freqplot, xferfcn

        to_tf = xferfcn._convert_to_transfer_function
        grid = freqplot._default_frequency_range
    except (ImportError, AttributeError):  # pragma: no cover - another python-control
        _, pms, _, _, wgc, _ = control.stability_margins(loop, returnall=True, method="frd")
        return np.atleast_1d(np.asarray(pms, float)), np.atleast_1d(np.asarray(wgc, float))
    sys = to_tf(loop)
    omega = grid(sys)
    frd = frdata.FRD(sys, omega[omega < np.pi / sys.dt], smooth=True)
    response = _smoothed_response(frd)

    def mod(w: Any) -> Any:
        return np.abs(response(w)) - 1

    w = frd.omega
    idx = np.where(np.diff(np.sign(mod(w))))[0]
    wc = np.array([scipy.optimize.brentq(mod, w[i], w[i + 1]) for i in idx])
    with np.errstate(all="ignore"):
        pm = np.remainder(np.angle(response(wc), deg=True), 360.0) - 180.0
    return np.atleast_1d(pm), wc


def _smoothed_response(frd: Any) -> Callable[[Any], Any]:
    """``w -> frd(1j * w)`` of a SISO smoothed FRD: python-control's spline, evaluated at
    every frequency in one ``splev`` call instead of one call per frequency (its
    ``FRD.eval`` loops in Python; the spline and the arithmetic are the same, so the
    values are the same to the bit). It reads the FRD's private spline (``_ifunc``); a
    python-control without it gets the FRD called as it is."""
    from scipy.interpolate import splev

    ifunc = getattr(frd, "_ifunc", None)
    if ifunc is None or np.shape(ifunc) != (1, 1):  # pragma: no cover - another python-control
        return lambda w: frd(1j * np.asarray(w))
    tck = ifunc[0, 0]

    def response(w: Any) -> Any:
        raw = splev(w, tck, der=0)
        return raw[0] + 1.0j * raw[1]

    return response


def _perturbed(params: BoucWenParams, parameter: str, delta: float) -> BoucWenParams:
    if parameter not in ("a1", "a2", "a3"):
        raise InputError(f"parameter must be one of a1, a2, a3, got {parameter!r}")
    return params.replace(**{parameter: getattr(params, parameter) * (1.0 + delta)})


def stability_interval(
    loop: ClosedLoop,
    *,
    parameter: str = "a1",
    bounds: tuple[float, float] = (-0.99, 10.0),
    rtol: float = 1e-3,
    estimator: str = "observer",
) -> tuple[float, float]:
    """Interval of relative error ``delta`` in ``parameter`` keeping the loop stable.

    Found by a scan (geometric steps away from 0) and bisection; the ends are
    accurate to ``rtol`` relative. ``loop`` and ``estimator`` as for :func:`analyze_loop`.
    """
    params, dt = loop.model, loop.dt

    def ok(d: float) -> bool:
        tp = _perturbed(params, parameter, d)
        A = loop_systems(loop, true_params=tp, estimator=estimator, lti=False).A_cl
        return stability(A, dt)[0]

    if not ok(0.0):
        return (math.nan, math.nan)
    ends = []
    for bound in (bounds[0], bounds[1]):
        sign = math.copysign(1.0, bound)
        steps = np.geomspace(1e-7, abs(bound), 120) * sign
        inside, outside = 0.0, None
        for d in steps:
            if ok(float(d)):
                inside = float(d)
            else:
                outside = float(d)
                break
        if outside is None:
            ends.append(float(bound))
            continue
        for _ in range(80):
            mid = 0.5 * (inside + outside)
            if ok(mid):
                inside = mid
            else:
                outside = mid
            if abs(outside - inside) <= rtol * abs(inside) + 1e-12:
                break
        ends.append(inside)
    return (ends[0], ends[1])


def mismatch_sweep(
    loop: ClosedLoop,
    *,
    parameter: str = "a1",
    deltas: Any = None,
    estimator: str = "observer",
) -> MismatchSweep:
    """Poles and margins of the loop for ``true parameter = (1 + delta) model``.

    Parameters
    ----------
    loop : ClosedLoop
        As for :func:`analyze_loop` (its ``model`` is the one perturbed).
    parameter : {"a1", "a2", "a3"}
    deltas : array_like, optional
        Relative errors; default ``[-5, -2, -1, -0.5, -0.1, 0, 0.1, 0.5, 1, 2, 5] %``.
    estimator : {"observer", "state"}
        As for :func:`analyze_loop`.

    Returns
    -------
    MismatchSweep
    """
    params = loop.model
    if deltas is None:
        deltas = np.array([-5, -2, -1, -0.5, -0.1, 0, 0.1, 0.5, 1, 2, 5]) / 100.0
    deltas = np.asarray(deltas, dtype=float)
    if deltas.ndim != 1 or not np.all(np.isfinite(deltas)) or np.any(deltas <= -1):
        raise InputError("deltas must be a 1-D array of finite relative errors > -1")
    st, rho, mre, gm, pm = [], [], [], [], []
    for d in deltas:
        tp = _perturbed(params, parameter, float(d))
        a = analyze_loop(loop, true_params=tp, estimator=estimator)
        st.append(a.stable)
        rho.append(a.spectral_radius if a.spectral_radius is not None else math.nan)
        mre.append(a.max_real_part)
        gm.append(a.gain_margin_db)
        pm.append(a.phase_margin if a.stable else math.nan)
    interval = stability_interval(loop, parameter=parameter, estimator=estimator)
    return MismatchSweep(
        parameter=parameter,
        deltas=deltas,
        stable=np.array(st, dtype=bool),
        spectral_radius=np.array(rho),
        max_real_part=np.array(mre),
        gain_margin_db=np.array(gm),
        phase_margin=np.array(pm),
        interval=interval,
    )
