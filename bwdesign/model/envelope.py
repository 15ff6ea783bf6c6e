"""Operating envelope: the input-rate bound ``|u'|`` <= udot_max a reference needs.

The certificates bound the hysteresis error through ``|u'|``, so the envelope of a
stage is the largest input rate it sees. For a reference ``x_d`` it is derived
from the *exact inverse* of the model: the input ``u_ff`` under which ``x1``
follows ``x_d`` exactly satisfies

    a3 u_ff = x_d'' + a2 x_d' + a1 x_d + a1 x3,   x3 the hysteresis driven by u_ff.

Rate independence lets us solve this sample by sample: at each time the new
input is the root of the monotone scalar equation
``a3 u - a1 H(h_k, u_k, u) = R(t)`` with ``H`` the closed-form hysteresis
increment, and the rate follows from differentiating the same relation,

    u' = (x_d''' + a2 x_d'' + a1 x_d') / (a3 - a1 dh/du),
    dh/du = alpha - beta s x3 - gamma |x3|,  s = sign(u').

The leading-order figure ``(a1/a3) max |x_d'|`` ignores the hysteresis
(``dh/du``) and the dynamics; the hysteresis raises the bound because just
after a reversal ``dh/du`` is largest and a given ``x_d'`` needs more ``u'``.
Impulses of ``x_d''`` at sharp triangle corners are dropped (a real loop
spreads them over its bandwidth); use ``corner_time`` to make them finite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..memo import Memo
from ..validate import UDOT_MAX, Range, integer, real
from .inverse import inverse_input
from .params import BoucWenParams
from .references import Reference

__all__ = ["Envelope", "derive_envelope", "given_envelope"]


@dataclass(frozen=True)
class Envelope:
    """An input-rate envelope for certification.

    Attributes
    ----------
    udot_max : float
        Bound on ``|u'|`` (V/s) used by the certificates.
    source : str
        ``"given"`` (stated in the config) or ``"reference"`` (derived).
    derived : float or None
        Hysteresis-aware inverse-model bound ``max |u_ff'|`` (V/s), before ``margin``.
    leading_order : float or None
        ``|a1/a3| max |x_d'|`` (V/s).
    margin : float
        Factor applied to ``derived``.
    u_range : (float, float) or None
        Range of the feedforward input (V).
    method : str
        How the number was obtained, for reports.
    """

    udot_max: float
    source: str
    derived: float | None = None
    leading_order: float | None = None
    margin: float = 1.0
    u_range: tuple[float, float] | None = None
    method: str = ""

    def to_dict(self) -> dict:
        return {
            "udot_max": self.udot_max,
            "source": self.source,
            "derived": self.derived,
            "leading_order": self.leading_order,
            "margin": self.margin,
            "u_range": list(self.u_range) if self.u_range else None,
            "method": self.method,
        }


def given_envelope(udot_max: float) -> Envelope:
    """An envelope stated directly (V/s), in :data:`bwdesign.validate.UDOT_MAX`."""
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_MAX)
    return Envelope(udot_max=udot_max, source="given", method="stated in the configuration")


def feedforward_input(
    params: BoucWenParams,
    reference: Reference,
    t: np.ndarray,
    *,
    h0: float = 0.0,
    allow_unbounded: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact-inverse input along ``t`` and its rate.

    The input is :func:`bwdesign.model.inverse.inverse_input` (a safeguarded Newton
    iteration per sample, the one the ``pi-bwff`` baseline and its C export run).

    Returns
    -------
    u : ndarray
        Input making x1 follow x_d exactly (V).
    udot : ndarray
        Its rate from the differentiated inverse (V/s).
    h : ndarray
        The hysteresis state along the path.
    """
    t = np.asarray(t, dtype=float)
    u, h = inverse_input(params, reference, t, h0=h0, allow_unbounded=allow_unbounded)
    a1, a2, a3 = params.a1, params.a2, params.a3
    _, vel, acc = reference.evaluate(t)
    num = reference.jerk(t) + a2 * acc + a1 * vel
    udot = np.empty_like(t)
    for k, (h_new, n_k) in enumerate(zip(h.tolist(), num.tolist(), strict=True)):
        rate = math.nan
        for s in (1.0, -1.0):
            slope = params.alpha - params.beta * s * h_new - params.gamma * abs(h_new)
            den = a3 - a1 * slope
            cand = n_k / den if den != 0 else math.inf
            if cand == 0 or math.copysign(1.0, cand) == s:
                rate = cand
                break
        udot[k] = rate
    return u, udot, h


def derive_envelope(
    params: BoucWenParams,
    reference: Reference,
    *,
    margin: float = 1.0,
    periods: int = 3,
    steps_per_period: int = 4000,
    allow_unbounded: bool = False,
) -> Envelope:
    """Derive ``udot_max`` from a reference through the exact inverse model.

    The inverse is run over ``periods`` periods from a zero hysteresis state and
    the maximum ``|u'|`` is taken over the last period, after the hysteresis has
    settled onto its periodic loop. For a step, over the rise (a sharp step has
    no finite rate and is refused).

    Parameters
    ----------
    params : BoucWenParams
    reference : Reference
    margin : float
        Factor >= 1 applied to the derived bound.
    periods : int
        Periods simulated (>= 2).
    steps_per_period : int
        Grid density for the inverse.

    Raises
    ------
    InputError
        A step with no rise time, a margin below 1, or a non-finite rate.
    """
    margin = real(margin, "envelope margin", within=Range(1.0, 1e6))
    periods = integer(periods, "periods", within=Range(2, 1000))
    steps_per_period = integer(steps_per_period, "steps_per_period", within=Range(10, 10**7))
    args = (params, reference, margin, periods, steps_per_period, allow_unbounded)
    return _ENVELOPES.get(args, lambda: _derive(*args))


#: :func:`derive_envelope`'s answers kept by their exact arguments, in this process (a
#: pure function of them; the commands and the report's parts ask for the stage's
#: envelope again).
_ENVELOPES: Memo[Envelope] = Memo(16)


def _derive(
    params: BoucWenParams,
    reference: Reference,
    margin: float,
    periods: int,
    steps_per_period: int,
    allow_unbounded: bool,
) -> Envelope:
    """:func:`derive_envelope` of checked arguments."""
    T = reference.period
    if T is not None:
        n = periods
        t = np.linspace(0.0, n * T, n * steps_per_period + 1)
        last = t >= (n - 1) * T
    else:
        rise = getattr(reference, "rise_time", 0.0)
        if rise <= 0:
            raise InputError(
                "a sharp step has no finite input rate; give the step a rise_time or "
                "state udot_max directly"
            )
        t0 = getattr(reference, "t_step", 0.0)
        t = np.linspace(t0 - 0.1 * rise, t0 + 1.1 * rise, steps_per_period + 1)
        last = np.ones_like(t, dtype=bool)
    u, udot, _ = feedforward_input(params, reference, t, allow_unbounded=allow_unbounded)
    if not np.all(np.isfinite(udot)):
        raise InputError("the inverse model gives a non-finite input rate for this reference")
    derived = float(np.max(np.abs(udot[last])))
    _, xdot, _ = reference.evaluate(t[last])
    leading = float(abs(params.a1 / params.a3) * np.max(np.abs(xdot)))
    return Envelope(
        udot_max=derived * margin,
        source="reference",
        derived=derived,
        leading_order=leading,
        margin=float(margin),
        u_range=(float(u[last].min()), float(u[last].max())),
        method=(
            f"max |u'| of the exact-inverse input for the reference ({reference.describe()}), "
            f"over the last of {periods if T else 1} period(s) on a {steps_per_period}-point "
            f"grid, times margin {margin:g}"
        ),
    )
