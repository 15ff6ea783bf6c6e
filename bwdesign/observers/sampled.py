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

from .base import _SampledObserver

__all__ = ["HysteresisObserver", "ExtendedStateObserver"]


class HysteresisObserver(_SampledObserver):
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


class ExtendedStateObserver(_SampledObserver):
    """Extended state observer (ESO, eq. 21): x3 treated as an unknown constant.

    Same constructor and interface as :class:`HysteresisObserver`; its predict
    holds x3hat instead of following the hysteresis model.
    """

    _hysteresis = False
    kind = "eso"
