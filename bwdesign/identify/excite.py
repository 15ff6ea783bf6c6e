"""Excitation design for a bench identification experiment, and simulated records.

An input that identifies all six parameters needs two things at once:

- **large reversals** over most of the amplifier range, at several
  amplitudes, so the hysteresis saturates on both branches and minor loops
  appear (this separates alpha, beta and gamma);
- **content around the resonance** (0.3 to 3 times the guessed natural
  frequency), so a1 and a2 are seen, not assumed.

``multisine``: a slow two-tone sweep of the range (f0 and 3.3 f0, f0 as high as
the rate limit allows up to a tenth of the resonance, at least 3/duration)
plus triangular minor loops over about three saturation lengths 1/(beta + gamma)
of the guess, plus a Schroeder-phased multisine over the resonance band. ``triangle-sweep``:
triangles from f0 up to a fraction of the resonance whose amplitude falls as
the frequency rises so the rate limit holds, which puts harmonics through the
resonance. Both are scaled to stay within ``[umin, umax]`` and ``|du/dt| <=
udot_max`` (checked on the sampled signal, |u[k+1] - u[k]| <= udot_max dt).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams
from ..model.plant import simulate_zoh
from .data import IdentificationData

__all__ = ["design_excitation", "simulate_record", "KINDS"]

KINDS = ("multisine", "triangle-sweep")


def _check(umin: float, umax: float, udot_max: float, duration: float, dt: float) -> int:
    for name, v in (
        ("umin", umin),
        ("umax", umax),
        ("udot_max", udot_max),
        ("duration", duration),
        ("dt", dt),
    ):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise InputError(f"{name} must be a finite number, got {v!r}")
    if umin >= umax:
        raise InputError(f"umin ({umin:g} V) must be below umax ({umax:g} V)")
    if udot_max <= 0 or duration <= 0 or dt <= 0:
        raise InputError("udot_max, duration and dt must be > 0")
    n = int(round(duration / dt))
    if n < 200:
        raise InputError(f"duration/dt = {n} samples; an identification record needs >= 200")
    if n > 5_000_000:
        raise InputError(f"duration/dt = {n} samples is more than 5e6; shorten the record")
    return n


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

    Parameters
    ----------
    guess : BoucWenParams
        Rough stage model (only its resonance sqrt(a1)/2pi is used).
    kind : {"multisine", "triangle-sweep"}
    umin, umax : float
        Amplifier range (V).
    udot_max : float
        Rate limit (V/s).
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
    """
    if kind not in KINDS:
        raise InputError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    n = _check(umin, umax, udot_max, duration, dt)
    t = np.arange(n) * dt
    mid, half = 0.5 * (umin + umax), 0.5 * (umax - umin)
    fr = math.sqrt(guess.a1) / (2 * math.pi)
    # as many large reversals as the rate limit allows (at least three cycles), a
    # decade below the resonance: hysteresis is rate independent, each cycle adds
    # information on alpha, beta, gamma
    f_rate = 0.6 * udot_max / (2 * math.pi * 1.69 * 0.8 * half)
    f0 = max(3.0 / duration, min(f_rate, fr / 10.0))
    fmax = 0.45 / dt
    rng = np.random.default_rng(seed)
    if kind == "multisine":
        slow = 0.7 * np.sin(2 * np.pi * f0 * t - 0.5 * np.pi) + 0.3 * np.sin(
            2 * np.pi * 3.3 * f0 * t
        )
        # minor loops: reversals over a few saturation lengths 1/(beta + gamma) of the
        # guess carry most of the information on the loop shape
        sat = 1.0 / max(guess.beta + guess.gamma, 1e-12)
        a_minor = min(3.0 * sat, 0.25 * half)
        f_minor = min(fr / 4.0, 0.3 * udot_max / (4.0 * a_minor), fmax / 4.0)
        minor = (
            (a_minor / half)
            * (2.0 / math.pi)
            * np.arcsin(np.sin(2 * np.pi * max(f_minor, 7.1 * f0) * t))
        )
        freqs = np.geomspace(0.3 * fr, min(3.0 * fr, fmax), 12)
        freqs = freqs[freqs > 10 * f0]
        fast = np.zeros(n)
        m = max(1, freqs.size)
        for i, f in enumerate(freqs):
            phase = math.pi * i * (i + 1) / m + 0.01 * rng.standard_normal()
            fast += np.sin(2 * np.pi * f * t + phase)
        if freqs.size:
            fast /= np.max(np.abs(fast))
        # the sweep, minor loops and the band share the range; all rate-limited
        u = _fit_limits(
            slow * (1 - a_minor / half) + minor, fast, mid, half, udot_max, dt, share=0.15
        )
    else:
        # triangle frequency rises geometrically from f0 to fr/3; amplitude capped by the rate
        f_end = max(f0, min(fr / 3.0, fmax / 3.0))
        f_inst = f0 * (f_end / f0) ** (t / duration)
        phase = np.cumsum(f_inst) * dt
        tri = 2.0 / math.pi * np.arcsin(np.sin(2 * np.pi * phase - 0.5 * np.pi))
        amp = np.minimum(1.0, 0.9 * udot_max / (4 * f_inst * half))
        u = mid + 0.95 * half * amp * tri
    u = np.clip(u, umin, umax)
    rate = np.max(np.abs(np.diff(u))) / dt
    if rate > udot_max * (1 + 1e-9):
        u = mid + (u - mid) * udot_max / rate
    return t, u


def _fit_limits(slow, fast, mid, half, udot_max, dt, *, share):
    a_fast = share * half
    a_slow = (1.0 - share) * 0.95 * half
    for _ in range(60):
        u = mid + a_slow * slow + a_fast * fast
        rate = np.max(np.abs(np.diff(u))) / dt
        if rate <= udot_max:
            return u
        a_fast *= 0.8 if a_fast * np.max(np.abs(np.diff(fast))) / dt > 0.3 * udot_max else 1.0
        a_slow *= 0.9 if a_slow * np.max(np.abs(np.diff(slow))) / dt > 0.5 * udot_max else 1.0
    return mid + a_slow * slow + a_fast * fast


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
