"""Initial conditions for a run that starts on the reference (``simulate --start-on-reference``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import InputError
from ..model.params import BoucWenParams
from ..model.references import Reference

__all__ = ["start_on_reference"]


def start_on_reference(params: BoucWenParams, reference: Reference) -> dict[str, Any]:
    """Plant state, estimate and held input that put the loop on the reference at t = 0.

    ``x0 = xhat0 = (x_d(0), x_d'(0), 0)`` and ``u_prev`` is the feedforward
    input that holds that state with no hysteresis,
    ``(x_d''(0) + a2 x_d'(0) + a1 x_d(0)) / a3`` (input unit). The report's
    tracking runs start here; ``bwdesign simulate --start-on-reference`` uses
    the same numbers.

    Parameters
    ----------
    params : BoucWenParams
    reference : Reference

    Returns
    -------
    dict
        ``x0``, ``xhat0`` (lists of 3 floats) and ``u_prev`` (float), keyword
        arguments of :func:`bwdesign.sim.simulate`.

    Examples
    --------
    >>> from bwdesign import preset, Sine
    >>> s = start_on_reference(preset("paper_experiment"), Sine(amplitude=80, offset=100,
    ...                        frequency=1))
    >>> s["x0"], round(s["u_prev"], 4)
    ([100.0, 502.6548245743669, 0.0], 73.3907)
    """
    if not isinstance(params, BoucWenParams):
        raise InputError(f"params must be a BoucWenParams, got {type(params).__name__}")
    if not isinstance(reference, Reference):
        raise InputError(
            "reference must be a bwdesign Reference (Sine, Triangle, Step or a subclass), "
            f"got {reference!r}"
        )
    xd0, vd0, ad0 = (float(np.asarray(a)) for a in reference.evaluate(0.0))
    return dict(
        x0=[xd0, vd0, 0.0],
        xhat0=[xd0, vd0, 0.0],
        u_prev=(ad0 + params.a2 * vd0 + params.a1 * xd0) / params.a3,
    )
