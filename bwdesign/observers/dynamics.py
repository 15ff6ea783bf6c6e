"""Plain-function observer steps, continuous right-hand sides and iosystem forms."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import ZOHModel, hysteresis_increment, phi
from .gains import check_disturbance_gains, check_gains

__all__ = ["phso_step", "eso_step", "phso_rhs", "eso_rhs", "phdo_rhs", "observer_iosystem"]


def phso_step(
    params: BoucWenParams,
    zoh: ZOHModel,
    K: np.ndarray,
    x: np.ndarray,
    u_prev: float,
    u: float,
    z: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    """One predict/update of the PHSO as a plain function.

    Returns
    -------
    (x_prior, x_post) : ndarrays, shape (3,)
    """
    h = hysteresis_increment(params, float(x[2]), float(u_prev), float(u))
    prior = zoh.F @ np.array([x[0], x[1], h]) + zoh.g * u
    post = prior if z is None else prior + K * (z - prior[0])
    return prior, post


def eso_step(
    params: BoucWenParams,
    zoh: ZOHModel,
    K: np.ndarray,
    x: np.ndarray,
    u_prev: float,
    u: float,
    z: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    """One predict/update of the ESO as a plain function (x3 held in the predict)."""
    prior = zoh.F @ np.asarray(x, dtype=float) + zoh.g * u
    post = prior if z is None else prior + K * (z - prior[0])
    return prior, post


def phso_rhs(
    params: BoucWenParams, gains: Any, xhat: np.ndarray, u: float, udot: float, y: float
) -> np.ndarray:
    """Continuous PHSO, paper eq. (3): the model copy plus injection on ``y - x1hat``.

    Parameters
    ----------
    params : BoucWenParams
    gains : sequence of float, length 3
        Continuous gains (l1 in 1/s, l2 in 1/s^2, l3 in 1/s); not validated here
        (use :func:`check_gains`).
    xhat : array_like, shape (3,)
        Estimate (x1 displacement, x2 velocity, x3 hysteresis; length unit, length unit/s,
        length unit).
    u : float
        Input (V).
    udot : float
        Input rate u' (V/s); the PHSO needs it for the hysteresis copy phi(u', x3hat).
    y : float
        Measured displacement (length unit).

    Returns
    -------
    ndarray, shape (3,)
        d xhat / dt.
    """
    l1, l2, l3 = gains
    x1, x2, x3 = xhat
    r = y - x1
    return np.array(
        [
            x2 + l1 * r,
            -params.a1 * (x1 + x3) - params.a2 * x2 + params.a3 * u + l2 * r,
            phi(params, udot, x3) + l3 * r,
        ]
    )


def eso_rhs(
    params: BoucWenParams, gains: Any, xhat: np.ndarray, u: float, udot: float, y: float
) -> np.ndarray:
    """Continuous ESO, paper eq. (21): ``x3hat' = l3 (y - x1hat)`` (no hysteresis model).

    Same arguments as :func:`phso_rhs`; ``udot`` is accepted for a common signature
    and ignored.
    """
    l1, l2, l3 = gains
    x1, x2, x3 = xhat
    r = y - x1
    return np.array(
        [
            x2 + l1 * r,
            -params.a1 * (x1 + x3) - params.a2 * x2 + params.a3 * u + l2 * r,
            l3 * r,
        ]
    )


def phdo_rhs(
    params: BoucWenParams, gains: Any, xhat: np.ndarray, u: float, udot: float, y: float
) -> np.ndarray:
    """Continuous disturbance hysteresis observer (:class:`DisturbanceHysteresisObserver`).

    ``xhat = (x1, x2, x3, d)``; ``gains = (l1, l2, l3, l4)`` (1/s, 1/s^2, 1/s, 1/s), not
    validated here. The linear part sees ``x3 + d``; ``d' = l4 (y - x1hat)``.

    Returns
    -------
    ndarray, shape (4,)
        d xhat / dt.
    """
    l1, l2, l3, l4 = gains
    x1, x2, x3, d = xhat
    r = y - x1
    return np.array(
        [
            x2 + l1 * r,
            -params.a1 * (x1 + x3 + d) - params.a2 * x2 + params.a3 * u + l2 * r,
            phi(params, udot, x3) + l3 * r,
            l4 * r,
        ]
    )


_RHS = {"phso": phso_rhs, "eso": eso_rhs, "phdo": phdo_rhs}


def observer_iosystem(
    params: BoucWenParams,
    gains: Any,
    *,
    kind: str = "phso",
    name: str | None = None,
    allow_unbounded: bool = False,
):
    """The continuous observer as a python-control ``NonlinearIOSystem``.

    Inputs ``u`` (V), ``udot`` (V/s) and ``y`` (measured displacement, length
    unit); states and outputs ``xhat[0]``, ``xhat[1]``, ``xhat[2]`` (the
    estimate). Signal names follow python-control's vector convention, so
    ``control.interconnect`` connects ``y`` to a plant output named ``y`` and
    ``u``/``udot`` to external inputs of the same names, and ``'xhat'`` selects
    all three outputs.

    Parameters
    ----------
    params : BoucWenParams
    gains : array_like, shape (3,)
        Continuous gains (l1 in 1/s, l2 in 1/s^2, l3 in 1/s), checked against the
        Hurwitz conditions (4).
    kind : {"phso", "eso", "phdo"}
        Hysteresis observer (eq. 3), extended state observer (eq. 21), or the
        disturbance hysteresis observer (:func:`phdo_rhs`; four gains, four states).
    name : str, optional
        System name (default: ``kind``).
    allow_unbounded : bool
        Accept parameters outside the bounded class.

    Returns
    -------
    control.NonlinearIOSystem

    Raises
    ------
    GainError
        Gains of the wrong length, non-finite, or violating conditions (4).
    ValueError
        Unknown ``kind``.

    Examples
    --------
    >>> import numpy as np, control
    >>> from bwdesign import preset
    >>> from bwdesign.model.plant import rhs
    >>> p = preset("paper_experiment")
    >>> plant = control.nlsys(lambda t, x, u, _: rhs(p, x, u[0], u[1]),
    ...                       lambda t, x, u, _: x[:1], inputs=["u", "udot"],
    ...                       states=3, outputs=["y"], name="plant")
    >>> obs = observer_iosystem(p, (8.0, 64.0, -512.0))
    >>> loop = control.interconnect([plant, obs], inplist=["u", "udot"],
    ...                             outlist=["y", "xhat"])
    >>> t = np.linspace(0.0, 0.05, 51)
    >>> resp = control.input_output_response(loop, t, [np.full_like(t, 10.0), 0 * t],
    ...                                      initial_state=[1.0, 0, 0, 0, 0, 0])
    >>> resp.outputs.shape
    (4, 51)
    """
    import control  # heavy import, only needed here

    if kind not in _RHS:
        raise InputError(f"kind must be 'phso', 'eso' or 'phdo', got {kind!r}")
    require_bounded(params, allow_unbounded)
    check = check_disturbance_gains if kind == "phdo" else check_gains
    g = tuple(check(params, gains).tolist())
    f = _RHS[kind]

    def updfcn(t, x, u, _params):
        return f(params, g, x, u[0], u[1], u[2])

    def outfcn(t, x, u, _params):
        return x

    xhat = [f"xhat[{i}]" for i in range(len(g))]
    return control.nlsys(
        updfcn,
        outfcn,
        inputs=["u", "udot", "y"],
        states=list(xhat),
        outputs=list(xhat),
        name=name or kind,
    )
