"""A true plant as signed changes of the model's parameters: ``a1=+2%,alpha=-0.01``.

``NAME=+W%`` adds ``W/100 |value|``, ``NAME=-W`` subtracts ``W``: the arithmetic of an
:class:`~bwdesign.model.uncertainty.UncertaintyBox` corner (``value +- half-width``), so
:func:`corner_text` writes a corner that :func:`apply_mismatch` rebuilds bit for bit
(``bwdesign simulate --mismatch``).
"""

from __future__ import annotations

import math

from ..errors import InputError
from ..validate import SIGNAL, parse_real
from .params import MODEL_FIELDS, BoucWenParams
from .uncertainty import UncertaintyBox

__all__ = ["apply_mismatch", "corner_text"]


def apply_mismatch(text: str, params: BoucWenParams, *, name: str = "mismatch") -> BoucWenParams:
    """``params`` with the changes of ``text`` (module docstring).

    Raises
    ------
    InputError
        An item that is not ``NAME=CHANGE`` with a model parameter, a name given twice,
        a change that is not a finite number, no item.
    """
    changes: dict[str, float] = {}
    for item in filter(None, (s.strip() for s in str(text).split(","))):
        key, sep, value = (v.strip() for v in item.partition("="))
        if not sep or key not in MODEL_FIELDS or key in changes:
            raise InputError(
                f"{name}: expected NAME=CHANGE (a1=+2% relative, alpha=-0.01 absolute), each "
                f"NAME once among {', '.join(MODEL_FIELDS)}, got {item!r}"
            )
        rel = value.endswith("%")
        w = parse_real(value[:-1] if rel else value, f"{name}: {key}", within=SIGNAL)
        v = getattr(params, key)
        hw = abs(w) / 100 * abs(v) if rel else abs(w)
        changes[key] = v - hw if w < 0 else v + hw
    if not changes:
        raise InputError(f"{name}: no parameter given")
    return params.replace(**changes, name=f"{params.name}/mismatch")


def _percent(w: float) -> str | None:
    """A decimal ``s`` with ``float(s) / 100 == w`` (None when none is near ``100 w``)."""
    x = 100 * w
    for _ in range(8):
        if float(repr(x)) / 100 == w:
            return repr(x)
        x = math.nextafter(x, math.inf if float(repr(x)) / 100 < w else -math.inf)
    return None


def corner_text(box: UncertaintyBox, params: BoucWenParams, corner: BoucWenParams) -> str:
    """The ``--mismatch`` text of ``corner`` (a vertex of ``box`` around ``params``)."""
    items = []
    for key, (kind, w) in box.widths.items():
        v, c = getattr(params, key), getattr(corner, key)
        if c == v:
            continue
        sign = "+" if c > v else "-"
        pct = _percent(w) if kind == "rel" else None
        items.append(
            f"{key}={sign}{pct}%" if pct else f"{key}={sign}{box.half_width(key, params)!r}"
        )
    return ",".join(items)
