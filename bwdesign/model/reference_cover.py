"""Bounds over *every* time of linear functionals of a reference and its next samples.

A sampled loop sees the reference through ``sigma(t) = (x_d, x_d', x_d'')`` at ``t``,
``t + dt`` and ``t + 2 dt`` (9 numbers, in that order): its feedforward, its
one-step reference terms and their increments are linear in ``sigma(t_k)``. A
certificate that holds "in steady state" needs ``sup_k |L sigma(t_k)|`` over all
samples ``k >= 0``, not over a window: a step three seconds in must be seen.

:func:`sup_abs` bounds ``sup_t |L sigma(t)|`` over every ``t >= 0`` (so over every
sample instant, whatever the alignment of the sampling with the reference):

- the domain is one period for a periodic reference (every phase), or
  ``[0, settles_at]`` for a reference that is constant from ``settles_at`` on (the
  value at ``settles_at`` is the value for ever after);
- it is cut at every breakpoint ``b`` of the reference and at ``b - dt``, ``b - 2 dt``,
  so that ``sigma`` is smooth on each piece; each piece is evaluated on a grid of
  spacing at most ``dt / refine`` (only its ends where the reference is constant
  there), at its ends from the inside and at the breakpoints themselves;
- between grid points ``f = L sigma`` exceeds the larger end value by at most
  ``h^2/8 sup |f''|`` (the error of linear interpolation), near a piece's end by at
  most ``r |f'| + r^2/2 sup |f''|`` (Taylor; ``f'`` exactly, from the reference's own
  derivatives, :meth:`~bwdesign.model.references.Reference.jerk` included), with
  ``sup |f''|`` from
  :meth:`~bwdesign.model.references.Reference.derivative_bounds` written in the
  difference basis ``(s(t), s(t+dt) - s(t), s(t+2dt) - 2 s(t+dt) + s(t))``, so that
  the nearly cancelling functionals a sampled loop produces (an increment, a second
  difference) keep a margin of their own size. That margin is added: the result is
  an upper bound, not a sample maximum.

A reference that states neither a period nor a settling time, or does not
implement :meth:`~bwdesign.model.references.Reference.breakpoints`,
:meth:`~bwdesign.model.references.Reference.derivative_bounds` and
:meth:`~bwdesign.model.references.Reference.jerk`, cannot be covered:
:func:`require_coverable` says so (an :class:`~bwdesign.errors.InputError`).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from .references import Reference

__all__ = ["SIGMA", "require_coverable", "sup_abs", "cover_domain"]

#: The 9 entries of ``sigma(t)``, in order.
SIGMA = (
    "x_d(t)",
    "x_d'(t)",
    "x_d''(t)",
    "x_d(t+dt)",
    "x_d'(t+dt)",
    "x_d''(t+dt)",
    "x_d(t+2dt)",
    "x_d'(t+2dt)",
    "x_d''(t+2dt)",
)
#: Grid points per sample time on the pieces where the reference moves.
REFINE = 16
#: At most this many grid points in all (the refinement drops towards 1 per sample).
MAX_POINTS = 400_000
#: Refused: a reference whose moving part spans more samples than this.
MAX_SAMPLES = 2_000_000


def require_coverable(reference: Reference, dt: float) -> tuple[float, float]:
    """Check that :func:`sup_abs` can cover ``reference``; return its domain ``(t0, t1)``.

    Raises
    ------
    InputError
        Not a :class:`Reference`; neither periodic nor settling; a method missing;
        a moving part longer than :data:`MAX_SAMPLES` samples.
    """
    if not isinstance(reference, Reference):
        raise InputError(f"reference must be a bwdesign Reference, got {type(reference).__name__}")
    name = type(reference).__name__
    try:
        reference.breakpoints(0.0, 0.0)
        reference.derivative_bounds(0.0, 1.0)
        reference.jerk(np.zeros(1))
    except NotImplementedError:
        raise InputError(
            f"the reference {name} does not state its breakpoints, derivative bounds and jerk "
            "(Reference.breakpoints, Reference.derivative_bounds, Reference.jerk): a "
            "certificate covers the whole reference at every time and cannot cover this one"
        ) from None
    t0, t1 = cover_domain(reference)
    if (t1 - t0) / dt > MAX_SAMPLES:
        raise InputError(
            f"the reference {name} moves over {t1 - t0:.6g} s, {(t1 - t0) / dt:.3g} samples of "
            f"dt = {dt:g} s; a certificate covers at most {MAX_SAMPLES:.0e} samples of it"
        )
    return t0, t1


def cover_domain(reference: Reference) -> tuple[float, float]:
    """The times whose values cover every ``t >= 0``: one period, or ``[0, settles_at]``."""
    name = type(reference).__name__
    period, settles = reference.period, reference.settles_at
    if period is not None:
        period = float(period)
        if not (math.isfinite(period) and period > 0):
            raise InputError(f"the reference {name} states a period of {period!r} s")
        return 0.0, period
    if settles is not None:
        settles = float(settles)
        if not math.isfinite(settles):
            raise InputError(f"the reference {name} states a settling time of {settles!r} s")
        return 0.0, max(settles, 0.0)
    raise InputError(
        f"the reference {name} is neither periodic (Reference.period) nor constant after a "
        "stated time (Reference.settles_at): a certificate covers the whole reference at every "
        "time and cannot cover this one"
    )


def _sigma(reference: Reference, t: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``sigma`` and its time derivative at times ``t``: two arrays of shape ``(9, len(t))``."""
    rows, rates = [], []
    for shift in (0.0, dt, 2 * dt):
        x, v, a = (np.asarray(w, float) for w in reference.evaluate(t + shift))
        rows += [x, v, a]
        rates += [v, a, np.asarray(reference.jerk(t + shift), float)]
    return np.array(rows), np.array(rates)


def _bounds(reference: Reference, a: float, b: float) -> list[float]:
    bounds = [float(x) for x in reference.derivative_bounds(a, b)]
    if len(bounds) != 4 or not all(math.isfinite(x) and x >= 0 for x in bounds):
        raise InputError(
            f"the reference {type(reference).__name__} states derivative bounds {bounds!r} on "
            f"({a:g}, {b:g}) s: four finite numbers >= 0 are needed"
        )
    return bounds


def _curvature(reference: Reference, a: float, b: float, dt: float) -> np.ndarray:
    """Bounds on the second time derivative of each difference-basis entry over ``(a, b)``."""
    _, acc, jerk, snap = _bounds(reference, a, b + 2 * dt)
    # per signal s in (x_d, x_d', x_d''): bounds on its 2nd, 3rd and 4th derivatives
    # (inf: not stated), then on the 2nd derivative of s, of s(t + dt) - s(t) and of
    # s(t + 2 dt) - 2 s(t + dt) + s(t)
    out = []
    for d2, d3, d4 in ((acc, jerk, snap), (jerk, snap, math.inf), (snap, math.inf, math.inf)):
        out += [d2, min(2 * d2, dt * d3), min(4 * d2, 2 * dt * d3, dt * dt * d4)]
    return np.array(out)  # varsigma's order: (x, dx, d2x, v, dv, d2v, a, da, d2a)


#: sigma = T @ varsigma with varsigma = (x, dx, d2x, v, dv, d2v, a, da, d2a).
_T = np.zeros((9, 9))
for _i in range(3):  # signal i: x_d, x_d', x_d''
    _s0, _d1, _d2 = 3 * _i, 3 * _i + 1, 3 * _i + 2
    _T[_i, _s0] = 1.0  # s(t)
    _T[3 + _i, [_s0, _d1]] = 1.0  # s(t + dt) = s + ds
    _T[6 + _i, [_s0, _d1, _d2]] = (1.0, 2.0, 1.0)  # s(t + 2dt) = s + 2 ds + d2s


def sup_abs(reference: Reference, dt: float, L: np.ndarray, *, refine: int = REFINE) -> np.ndarray:
    """Upper bounds on ``sup_{t >= 0} |L sigma(t)|`` per row of ``L`` (shape ``(m, 9)``).

    See the module docstring. With ``f = L sigma``, ``C`` a bound on ``|f''|`` over a
    piece and ``h`` its grid spacing: between two grid points ``|f| <= max(|f(t_i)|,
    |f(t_i+1)|) + h^2 C / 8`` (the linear interpolant's error); within ``r`` of a
    piece's end ``|f| <= |f(t_e)| + r |f'(t_e)| + r^2 C / 2`` (Taylor); plus a
    float rounding allowance. So the result is never below the true supremum.
    """
    L = np.atleast_2d(np.asarray(L, float))
    if L.ndim != 2 or L.shape[1] != 9:
        raise InputError(f"L must have 9 columns (sigma), got shape {L.shape}")
    t0, t1 = require_coverable(reference, dt)
    LT = np.abs(L @ _T)
    bps = np.asarray(reference.breakpoints(t0 - 2 * dt, t1 + 2 * dt), float)
    knots = np.concatenate([[t0, t1], bps, bps - dt, bps - 2 * dt])
    knots = np.unique(knots[(knots >= t0) & (knots <= t1)])
    pieces = list(zip(knots[:-1], knots[1:], strict=True))
    curv = [_curvature(reference, a, b, dt) for a, b in pieces]
    moving = [any(_bounds(reference, a, b + 2 * dt)) for a, b in pieces]
    span = sum(b - a for (a, b), m in zip(pieces, moving, strict=True) if m)
    refine = max(1, min(int(refine), int(MAX_POINTS * dt / max(span, dt))))
    h_max = dt / refine
    best, scale = _values(L, reference, knots, dt)  # the knots' own values
    for (a, b), c, mv in zip(pieces, curv, moving, strict=True):
        F2 = LT @ c  # bound on |f''| over the piece, per row
        eps = max(1e-9 * (b - a), 8 * float(np.spacing(max(abs(a), abs(b), dt))))
        if b - a <= 4 * eps:  # a sliver: Taylor from its middle
            ends, r = np.array([0.5 * (a + b)]), 0.5 * (b - a)
        else:  # a grid inside the piece, spacing <= h_max where it moves, Taylor at its ends
            n = max(1, math.ceil((b - a - 2 * eps) / h_max)) if mv else 1
            t = np.linspace(a + eps, b - eps, n + 1)
            h = (b - a - 2 * eps) / n
            vals, sc = _values(L, reference, t, dt)
            best = np.maximum(best, vals + h * h / 8 * F2)
            scale = np.maximum(scale, sc)
            ends, r = np.array([a + eps, b - eps]), eps
        vals, sc = _values(L, reference, ends, dt, reach=r)
        best = np.maximum(best, vals + 0.5 * r * r * F2)
        scale = np.maximum(scale, sc)
    # rounding: each value is a sum of at most 9 products, each exact to half an ulp
    return best + 32 * np.finfo(float).eps * scale


def _values(
    L: np.ndarray, reference: Reference, t: np.ndarray, dt: float, *, reach: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Per row: ``max_i |f(t_i)| + reach |f'(t_i)|`` and ``max_i |L| |sigma(t_i)|`` (for
    the rounding allowance), in chunks of ~16 MB."""
    step = max(1, 2_000_000 // max(L.shape[0], 1))
    out, scale = np.zeros(L.shape[0]), np.zeros(L.shape[0])
    absL = np.abs(L)
    for i in range(0, len(t), step):
        sig, rate = _sigma(reference, t[i : i + step], dt)
        val = np.abs(L @ sig)
        if reach:
            val += reach * np.abs(L @ rate)
        out = np.maximum(out, val.max(axis=1))
        scale = np.maximum(scale, (absL @ np.abs(sig)).max(axis=1))
    return out, scale
