"""Excitation design for a bench identification experiment, and simulated records.

An input that identifies all six parameters needs two things at once:

- **large reversals** over most of the amplifier range, at several
  amplitudes, so the hysteresis saturates on both branches and minor loops
  appear (this separates alpha, beta and gamma);
- **content around the resonance** (0.3 to 3 times the guessed natural
  frequency), so a1 and a2 are seen, not assumed.

``multisine``: a slow two-tone sweep of the range (f0 and 3.3 f0, f0 as high as
the rate limit allows up to a tenth of the resonance, at least 3/duration
while the rate allows it at the full range, else slower, down to one sweep)
plus triangular minor loops over about three saturation lengths 1/(beta + gamma)
of the guess, plus a Schroeder-phased multisine over the resonance band. ``triangle-sweep``:
one full-range triangle at f0, then triangles up to a fraction of the resonance
whose amplitude falls as the frequency rises so the rate limit holds, which puts
harmonics through the resonance. Both span the range asked to within
:data:`RANGE_MARGIN` (2.5 %) of each end and keep ``|du/dt| <= udot_max``
(checked on the sampled signal, ``|u[k+1] - u[k]| <= udot_max dt``); a rate too low
to cross the range once over the record (:func:`smallest_rate`) is refused.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams
from ..model.plant import check_dt, simulate_zoh
from ..validate import POSITIVE, SIGNAL, UDOT_MAX, real
from .data import IdentificationData

__all__ = ["design_excitation", "smallest_rate", "simulate_record", "KINDS", "RANGE_MARGIN"]

#: The excitations :func:`design_excitation` designs (``bwdesign excite --kind``).
KINDS = ("multisine", "triangle-sweep")
#: Fraction of the amplifier range kept clear at each end: the input reaches to within
#: this of ``umin`` and of ``umax``, so it spans 95 % of the range asked.
RANGE_MARGIN = 0.025
#: Fewest slow sweeps of the range over the record.
MIN_SWEEPS = 1.0


def _check(umin: float, umax: float, udot_max: float, duration: float, dt: float) -> int:
    umin = real(umin, "umin (V)", within=SIGNAL)
    umax = real(umax, "umax (V)", within=SIGNAL)
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_MAX)
    duration = real(duration, "duration (s)", within=POSITIVE)
    dt = check_dt(dt)
    if umin >= umax:
        raise InputError(f"umin ({umin:g} V) must be below umax ({umax:g} V)")
    n = int(round(duration / dt))
    if n < 200:
        raise InputError(f"duration/dt = {n} samples; an identification record needs >= 200")
    if n > 5_000_000:
        raise InputError(f"duration/dt = {n} samples is more than 5e6; shorten the record")
    return n


def _rate(u: np.ndarray, dt: float) -> float:
    """Largest |u[k+1] - u[k]| / dt (V/s)."""
    return float(np.max(np.abs(np.diff(u)))) / dt


def _sweep(t: np.ndarray, f0: float) -> np.ndarray:
    """The slow two-tone sweep of the range, peak about 1."""
    return 0.7 * np.sin(2 * np.pi * f0 * t - 0.5 * np.pi) + 0.3 * np.sin(2 * np.pi * 3.3 * f0 * t)


def _span(s: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``s`` mapped affinely onto ``[lo, hi]`` (its minimum to lo, its maximum to hi)."""
    return lo + (s - s.min()) * ((hi - lo) / float(np.ptp(s)))


def smallest_rate(
    *, umin: float, umax: float, duration: float, dt: float, kind: str = "multisine"
) -> float:
    """The smallest ``udot_max`` (V/s) at which :func:`design_excitation` uses the range asked.

    The rate of the slowest design: :data:`MIN_SWEEPS` sweep(s) of
    ``[umin, umax]`` (less :data:`RANGE_MARGIN` at each end) over ``duration``,
    without minor loops or a resonance band (for ``triangle-sweep``: its first
    triangle at ``MIN_SWEEPS / duration``). Below it the input could not cross the
    range: :func:`design_excitation` refuses such a rate instead of writing a
    nearly constant input.
    """
    if kind not in KINDS:
        raise InputError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    n = _check(umin, umax, 1.0, duration, dt)
    lo, hi = umin + RANGE_MARGIN * (umax - umin), umax - RANGE_MARGIN * (umax - umin)
    t = np.arange(n) * dt
    f0 = MIN_SWEEPS / duration
    if kind == "triangle-sweep":
        return 2.0 * (hi - lo) * f0 / 0.9  # one triangle at f0 within 0.9 of the rate
    return _rate(_span(_sweep(t, f0), lo, hi), dt)


def design_excitation(
    guess: BoucWenParams,
    *,
    kind: str = "multisine",
    umin: float,
    umax: float,
    udot_max: float,
    duration: float,
    dt: float,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """An input to play on the bench.

    The input spans ``[umin, umax]`` to within :data:`RANGE_MARGIN` of the range
    at each end (95 % of it) and keeps ``|u[k+1] - u[k]| <= udot_max dt``; where
    the rate limit does not allow the planned frequencies at that amplitude, the
    slow sweep and the minor loops are slowed (down to :data:`MIN_SWEEPS` sweep
    over the record) and the resonance band is made smaller, never the range.

    Parameters
    ----------
    guess : BoucWenParams
        Rough stage model (only its resonance sqrt(a1)/2pi is used).
    kind : {"multisine", "triangle-sweep"}
    umin, umax : float
        Amplifier range (V).
    udot_max : float
        Rate limit (V/s), at least :func:`smallest_rate`.
    duration : float
        Length (s).
    dt : float
        Sample time (s).
    seed : int
        Seed of the multisine phases' tie-breaking jitter.

    Returns
    -------
    t, u : ndarray
        Times (s) and held input (V).

    Raises
    ------
    InputError
        Bad numbers, too few or too many samples, or ``udot_max`` below
        :func:`smallest_rate` (the message states it).
    """
    if kind not in KINDS:
        raise InputError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    n = _check(umin, umax, udot_max, duration, dt)
    need = smallest_rate(umin=umin, umax=umax, duration=duration, dt=dt, kind=kind)
    if udot_max < need:
        raise InputError(
            f"udot_max = {udot_max:g} V/s is below the smallest usable {need:.4g} V/s for a "
            f"{kind} over [{umin:g}, {umax:g}] V in {duration:g} s (one sweep of the range); "
            "raise the rate limit, lengthen the record or narrow the range"
        )
    t = np.arange(n) * dt
    lo, hi = umin + RANGE_MARGIN * (umax - umin), umax - RANGE_MARGIN * (umax - umin)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    fr = math.sqrt(guess.a1) / (2 * math.pi)
    # as many large reversals as the rate limit allows (at least three cycles), a
    # decade below the resonance: hysteresis is rate independent, each cycle adds
    # information on alpha, beta, gamma
    f_rate = 0.6 * udot_max / (2 * math.pi * 1.69 * 0.8 * half)
    f0 = max(3.0 / duration, min(f_rate, fr / 10.0))
    if kind == "triangle-sweep":
        u = _triangle_sweep(t, dt, f0, fr, mid, half, udot_max)
        spanned = _span(u, lo, hi)  # the sampled peaks miss the ends by a fraction of a step
        u = spanned if _rate(spanned, dt) <= udot_max else u
    else:
        u = _multisine(guess, t, dt, f0, fr, lo, hi, udot_max, seed)
    u = np.clip(u, umin, umax)
    rate = _rate(u, dt)
    if rate > udot_max * (1 + 1e-9):  # pragma: no cover - each design keeps the rate
        u = mid + (u - mid) * udot_max / rate
    return t, u


def _triangle_sweep(t, dt, f0, fr, mid, half, udot_max) -> np.ndarray:
    """One full-range triangle at f0, then a geometric rise to fr/3 with a rate-capped amplitude.

    The amplitude cap ``c udot_max / (4 f half)`` falls as the frequency rises; its
    fall adds ``half |d amp/dt|`` to the rate, so ``c`` leaves room for it
    (``c = 0.95 / (1 + ln(f_end/f0) / (4 f0 T_rise))``) and the first triangle's
    frequency keeps ``4 f0 half <= c udot_max``, where the cap is still 1 (no jump).
    """
    duration = t.size * dt
    floor = MIN_SWEEPS / duration
    f_end = max(f0, min(fr / 3.0, 0.15 / dt))
    c = 0.9
    for _ in range(20):  # c and f1 depend on each other: a few rounds settle them
        # below the floor there is no rise (one triangle fills the record); else
        # 4 f1 half <= c udot_max, so the cap is 1 where the rise starts
        f1 = max(floor, min(f0, c * udot_max / (4 * half)))
        rise_time = duration - min(1.0 / f1, duration)
        safe = (
            0.95 / (1 + math.log(f_end / f1) / (4 * f1 * rise_time))
            if rise_time > 0 and f_end > f1
            else c
        )
        if safe >= c:
            break
        c = safe
    t1 = min(1.0 / f1, duration)
    rise = np.clip((t - t1) / max(duration - t1, dt), 0.0, 1.0)
    f_inst = f1 * (max(f_end, f1) / f1) ** rise
    phase = np.concatenate(([0.0], np.cumsum(f_inst[:-1]) * dt))
    tri = 2.0 / math.pi * np.arcsin(np.sin(2 * np.pi * phase - 0.5 * np.pi))
    amp = np.where(t < t1, 1.0, np.minimum(1.0, c * udot_max / (4 * f_inst * half)))
    return mid + half * amp * tri


def _multisine(guess, t, dt, f0, fr, lo, hi, udot_max, seed) -> np.ndarray:
    """Sweep + minor loops + resonance band, spanning ``[lo, hi]`` within the rate limit.

    The band's share of the amplitude shrinks first; when the sweep and the minor
    loops alone exceed the rate at the full span, the sweep is slowed (by 0.8 a
    step; the minor loops keep their frequency, which carries the loop shape)
    down to :data:`MIN_SWEEPS` sweep over the record, where the minor loops are
    dropped last. :func:`smallest_rate` is the rate of that last design, so a
    ``udot_max`` at or above it always ends here.
    """
    half = 0.5 * (hi - lo)
    floor = MIN_SWEEPS / (t.size * dt)
    fmax = 0.45 / dt
    # minor loops: reversals over a few saturation lengths 1/(beta + gamma) of the
    # guess carry most of the information on the loop shape
    sat = 1.0 / max(guess.beta + guess.gamma, 1e-12)
    a_minor = min(3.0 * sat, 0.25 * half)
    f_minor = min(fr / 4.0, 0.3 * udot_max / (4.0 * a_minor), fmax / 4.0)
    freqs = np.geomspace(0.3 * fr, min(3.0 * fr, fmax), 12)
    jitter = 0.01 * np.random.default_rng(seed).standard_normal(freqs.size)
    bands: dict[int, np.ndarray] = {}
    slowdown = 1.0
    while True:
        f_s = max(floor, f0 * slowdown)
        band = freqs[freqs > 10 * f_s]  # grows as the sweep slows: cache by size
        if band.size not in bands:
            fast = np.zeros(t.size)
            for i, f in enumerate(band):
                fast += np.sin(2 * np.pi * f * t + math.pi * i * (i + 1) / band.size + jitter[i])
            bands[band.size] = fast / np.max(np.abs(fast)) if band.size else fast
        fast = bands[band.size]
        minor = (2.0 / math.pi) * np.arcsin(np.sin(2 * np.pi * max(f_minor, 7.1 * f_s) * t))
        for rho in (a_minor / half, 0.0) if f_s == floor else (a_minor / half,):
            slow = _sweep(t, f_s) * (1 - rho) + rho * minor
            share = 0.15 if band.size else 0.0
            while True:
                u = _span(slow * (1 - share) + share * fast, lo, hi)
                if _rate(u, dt) <= udot_max or (f_s == floor and rho == 0.0 and share == 0.0):
                    return u
                share = share * 0.8 if share > 1e-3 else 0.0
                if share == 0.0 and _rate(_span(slow, lo, hi), dt) > udot_max:
                    break
        slowdown *= 0.8


def simulate_record(
    params: BoucWenParams,
    u: np.ndarray,
    dt: float,
    *,
    noise: float = 0.01,
    offset: float = 0.0,
    x0: tuple[float, float, float] = (0.0, 0.0, 0.0),
    seed: int = 0,
    amplifier_lag: float | None = None,
) -> IdentificationData:
    """A simulated bench record: the exact ZOH plant plus Gaussian sensor noise.

    Parameters
    ----------
    params : BoucWenParams
    u : ndarray
        Held input (V).
    dt : float
        Sample time (s).
    noise : float
        Sensor noise standard deviation (µm); 0.01 is 10 nm.
    offset : float
        Sensor offset (µm).
    x0 : tuple
        Initial state (µm, µm/s, µm).
    seed : int
        Seed of the noise.
    amplifier_lag : float, optional
        Time constant (s) of an unmodelled first-order amplifier between the
        command and the stage (the plant then sees the lagged voltage, exactly
        discretised for a held command).
    """
    u = np.asarray(u, dtype=float)
    drive = u
    if amplifier_lag is not None:
        a = math.exp(-dt / amplifier_lag)
        v = np.empty_like(u)
        state = u[0]
        for k, uk in enumerate(u):
            v[k] = state
            state = a * state + (1 - a) * uk
        # the plant sees the amplifier output sampled at each step (held over the step)
        drive = np.concatenate((v[1:], [a * v[-1] + (1 - a) * u[-1]]))
    x = simulate_zoh(params, drive, dt, np.asarray(x0, float), u_prev=float(drive[0]))
    rng = np.random.default_rng(seed)
    y = x[1:, 0] + offset + noise * rng.standard_normal(u.size)
    t = np.arange(u.size) * dt
    return IdentificationData.from_arrays(t, u, y, source=f"simulated {params.name or 'stage'}")
