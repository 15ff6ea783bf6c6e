"""Hysteresis observer (PHSO, paper eq. 3) and extended state observer (ESO, eq. 21).

Both come in two forms:

- **Discrete, filterpy-style** classes for the sample rate a stage runs at:
  ``predict(u_k)`` carries the estimate from ``t_k`` to ``t_{k+1}`` with
  ``u_k`` held, propagating the model copy *exactly* (the closed-form
  hysteresis jump ``u_{k-1} -> u_k`` for the PHSO, then the zero-order-hold
  linear part); ``update(z)`` corrects with ``z = y(t_{k+1})``::

      x_prior = F [x1, x2, H(x3, u_{k-1}, u_k)] + g u_k        (PHSO)
      x_prior = F x + g u_k                                     (ESO: x3 held)
      x_post  = x_prior + K (z - x_prior[0])

- **Continuous-time** right-hand sides (:func:`phso_rhs`, :func:`eso_rhs`) for
  analysis and for the paper's continuous simulations, and the same observers
  as python-control ``NonlinearIOSystem`` objects (:func:`observer_iosystem`,
  ``as_iosystem()``) for ``control.interconnect`` and
  ``control.input_output_response``.

Continuous gains ``l`` map to the discrete correction ``K`` by pole matching:
the nominal discrete error matrix ``(I - K C) F`` gets the eigenvalues
``exp(lambda_i dt)`` of the continuous error matrix ``A0 - l C``
(:func:`discrete_gains`). As ``dt -> 0``, ``K ~ l dt`` and the discrete
observer converges to the continuous one.

Error dynamics of the discrete PHSO (used by the ``sampled`` certificate)::

    eps_post[k+1] = (I - K C) F diag(1, 1, rho_k) eps_post[k]

with ``rho_k`` the slope of the hysteresis jump map between the true and the
estimated state.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..model.params import BoucWenParams
from .base import SampledObserver
from .gains import (
    check_disturbance_discrete,
    check_disturbance_gains,
    disturbance_discrete_gains,
)

__all__ = ["HysteresisObserver", "ExtendedStateObserver", "DisturbanceHysteresisObserver"]


class HysteresisObserver(SampledObserver):
    """The paper's hysteresis observer (PHSO, eq. 3), sampled exactly.

    Parameters
    ----------
    params : BoucWenParams
    gains : array_like, shape (3,), optional
        Continuous gains (l1 in 1/s, l2 in 1/s^2, l3 in 1/s) satisfying the
        Hurwitz conditions (4); mapped to ``K`` by pole matching.
    dt : float
        Sample time (s).
    discrete : array_like, shape (3,), optional
        Discrete correction gains ``K`` instead of ``gains``.
    x0 : array_like, shape (3,), optional
        Initial estimate (default zeros).
    u_prev : float
        Input held before the first sample (V).
    allow_unbounded : bool
        Accept parameters outside the bounded class.

    Examples
    --------
    >>> from bwdesign import preset
    >>> obs = HysteresisObserver(preset("paper_experiment"), (8.0, 64.0, -512.0), 2e-4)
    >>> obs.predict(1.0); obs.update(0.0)
    >>> obs.x.shape
    (3,)
    """

    _hysteresis = True
    kind = "phso"


class ExtendedStateObserver(SampledObserver):
    """Extended state observer (ESO, eq. 21): x3 treated as an unknown constant.

    Same constructor and interface as :class:`HysteresisObserver`; its predict
    holds x3hat instead of following the hysteresis model.
    """

    _hysteresis = False
    kind = "eso"


class DisturbanceHysteresisObserver(SampledObserver):
    """Hysteresis observer with an integrating disturbance state (kind ``"phdo"``).

    States ``(x1, x2, x3, d)``: the PHSO's model copy plus a constant-disturbance
    state ``d`` that enters where the hysteresis does and integrates the
    innovation::

        x1' = x2 + l1 r
        x2' = -a1 x1 - a2 x2 - a1 (x3 + d) + a3 u + l2 r
        x3' = phi(u', x3) + l3 r             (the Bouc-Wen copy)
        d'  = l4 r                           r = y - x1hat

    ``d`` absorbs what the model gets wrong (an error in a1, a3, alpha, beta,
    gamma shows up as a slowly varying extra term beside ``a1 x3``), so the
    hysteresis copy is not dragged back into the hysteresis range at each
    reversal as the PHSO's is. Sampled exactly like the PHSO: the jump of
    ``x3`` in closed form, then the ZOH of the linear part with ``x3 + d``;
    ``d`` is held in the predict.

    What converges, and when (the error ``e = x - xhat``, true ``d = 0``):

    - **the lumped estimate** ``x3hat + dhat`` (with x1hat, x2hat) **always**:
      the linear part sees only ``w = x3 + d``; in the coordinates
      ``(e1, e2, ew = e3 + ed)`` the error is the PHSO's with the gain
      ``l3 + l4`` (Hurwitz by conditions (4)), driven by the hysteresis
      mismatch ``phi(u', x3) - phi(u', x3hat)`` (continuous) or
      ``-(1 - rho_k) e3`` (sampled, ``rho_k`` the jump-map slope). With
      ``l3 = 0`` (the default of the digital tuning) ``e3`` obeys the copy's
      own contraction, ``e3[k+1] = rho_k e3[k]`` with ``0 < rho_k <= 1``, so
      ``|e3|`` never grows and ``(1 - rho_k) |e3_k|`` is summable: the lumped
      error converges for every input. For ``l3 != 0`` the certificates of
      :mod:`bwdesign.certify.disturbance` check it.
    - **x3hat and dhat separately only while the input moves**: the linear
      part cannot tell ``x3`` from ``d``; the split is learnt from the
      hysteresis dynamics alone, and ``e3`` decays by the factor ``rho_k < 1``
      only on samples where ``u`` changes (``prod rho_k -> 0``). With a held
      input ``e3`` and ``ed = ew - e3`` stay where they are.

    Parameters
    ----------
    params : BoucWenParams
    gains : array_like, shape (4,), optional
        Continuous gains ``(l1 1/s, l2 1/s^2, l3 1/s, l4 1/s)``; ``(l1, l2, l3 + l4)``
        must satisfy conditions (4), ``l4 != 0``. Mapped to ``K`` by pole matching of
        the observable part (:func:`bwdesign.observers.gains.disturbance_discrete_gains`).
    dt : float
        Sample time (s).
    discrete : array_like, shape (4,), optional
        Discrete correction gains ``K = (k1, k2, k3, k4)`` instead of ``gains``.
    x0 : array_like, shape (4,), optional
        Initial estimate (default zeros).
    u_prev : float
        Input held before the first sample (V).
    allow_unbounded : bool
        Accept parameters outside the bounded class.

    Examples
    --------
    >>> from bwdesign import preset
    >>> obs = DisturbanceHysteresisObserver(preset("paper_experiment"),
    ...                                     (8.0, 64.0, 0.0, -512.0), 2e-4)
    >>> obs.predict(1.0); obs.update(0.0)
    >>> obs.x.shape, obs.x_lumped.shape
    ((4,), (3,))
    """

    _hysteresis = True
    _n = 4
    kind = "phdo"

    @staticmethod
    def _check_continuous(params: BoucWenParams, gains: Any) -> np.ndarray:
        return check_disturbance_gains(params, gains)

    @staticmethod
    def _discrete_from(params: BoucWenParams, gains: np.ndarray, dt: float) -> np.ndarray:
        return disturbance_discrete_gains(params, gains, dt)

    @staticmethod
    def _check_discrete(discrete: Any) -> np.ndarray:
        return check_disturbance_discrete(discrete)

    @staticmethod
    def _observable_K(K: np.ndarray) -> np.ndarray:
        return np.array([K[0], K[1], K[2] + K[3]])
