"""One style per series, the same in every figure bwdesign draws.

A series is named by its label; words in the label pick its look:

* the observer (``PHSO``, ``ESO``, ``PHDO``, ``UKF``) picks the colour (and a
  line width, widest first, so exactly overlapping runs stay visible);
* the tracking law (``eq. 12``, ``digital tuning``) picks the line style and
  the marker; a label without a law gets one per variant (the label without its
  observer word) or, with no variant, its observer's own line style;
* a gain set (``configured``, ``synthesised``) picks the colour where no observer is named;
* the reference or true state (``true``, ``desired``, ``x_d``) is solid black;
* bounds and limits drawn by the figures themselves are red.

A label none of these words name gets a colour from :data:`FALLBACK_COLORS`
(none of which is used above); colours and styles not fixed by words are given
in the order of first appearance in the figure (:class:`Styler`). So "PHSO (eq. 12)"
is dashed blue (``x`` markers in pole plots) in the tracking figure, the
estimation errors and anywhere else.
"""

from __future__ import annotations

import functools
import re
from typing import Any

__all__ = [
    "OBSERVER_COLORS",
    "OBSERVER_STYLES",
    "OBSERVER_WIDTHS",
    "LAW_STYLES",
    "LAW_COLORS",
    "GAIN_SET_COLORS",
    "REFERENCE_COLOR",
    "BOUND_COLOR",
    "FALLBACK_COLORS",
    "Styler",
    "series_style",
    "new_figure",
    "legend",
    "plain_tick_label",
    "plain_log_ticks",
]

OBSERVER_COLORS = {
    "PHSO": "tab:blue",
    "ESO": "tab:orange",
    "PHDO": "tab:green",
    "UKF": "tab:purple",
}
#: Line style of an observer's series when the label names no law.
OBSERVER_STYLES = {"PHSO": "--", "ESO": "-.", "PHDO": ":", "UKF": (0, (6, 2, 1, 2, 1, 2))}
#: Line width per observer: widest first, so a run that overlaps another exactly shows inside it.
OBSERVER_WIDTHS = {"PHSO": 2.4, "ESO": 1.8, "PHDO": 1.1, "UKF": 1.4}
#: Line style and marker per tracking law.
LAW_STYLES = {"eq. 12": ("--", "x"), "digital tuning": ("-", "o")}
#: Colour of a law's series where no observer is named (the loop-pole figure).
LAW_COLORS = {"eq. 12": "tab:brown", "digital tuning": "tab:olive"}
GAIN_SET_COLORS = {"configured": "tab:pink", "synthesised": "tab:cyan"}
REFERENCE_COLOR = "black"
BOUND_COLOR = "tab:red"
FALLBACK_COLORS = ("navy", "teal", "goldenrod", "indigo", "darkkhaki", "slategray")
_FALLBACK_STYLES = (("-", "s"), ("--", "^"), (":", "d"), ("-.", "v"))

_OBSERVER = re.compile(r"\b(PHSO|ESO|PHDO|UKF)\b", re.IGNORECASE)
_LAWS = {
    "eq. 12": re.compile(r"\beq\.?\s*\(?12\)?", re.IGNORECASE),
    "digital tuning": re.compile(r"\bdigital(\s+tuning)?\b", re.IGNORECASE),
}
_GAIN_SETS = {
    "configured": re.compile(r"\bconfigured\b", re.IGNORECASE),
    "synthesised": re.compile(r"\bsynthesi[sz]ed\b", re.IGNORECASE),
}
_REFERENCE = {"true", "desired", "x_d", "reference", "measured"}


def series_style(label: str) -> dict[str, Any]:
    """The style the words of ``label`` fix (keys ``color``, ``ls``, ``marker``, ``lw``).

    Keys the words do not fix are None (:class:`Styler` fills them).
    """
    if label.strip().lower() in _REFERENCE:
        return {"color": REFERENCE_COLOR, "ls": "-", "marker": None, "lw": 2.0}
    out: dict[str, Any] = {"color": None, "ls": None, "marker": None, "lw": None}
    m = _OBSERVER.search(label)
    obs = m.group(1).upper() if m else None
    law = next((k for k, rx in _LAWS.items() if rx.search(label)), None)
    gain_set = next((k for k, rx in _GAIN_SETS.items() if rx.search(label)), None)
    if obs is not None:
        out["color"], out["lw"] = OBSERVER_COLORS[obs], OBSERVER_WIDTHS[obs]
    elif law is not None:
        out["color"] = LAW_COLORS[law]
    elif gain_set is not None:
        out["color"] = GAIN_SET_COLORS[gain_set]
    if law is not None:
        out["ls"], out["marker"] = LAW_STYLES[law]
    return out


def _variant(label: str) -> str:
    """``label`` without the words that fix a colour (what tells two runs of one observer apart)."""
    text = _OBSERVER.sub("", label)
    for rx in _GAIN_SETS.values():
        text = rx.sub("", text)
    return " ".join(text.split()).strip(" ,:;|()-")


class Styler:
    """Styles for one figure: :func:`series_style`, the rest filled in order of appearance.

    The line style is the law's; else, when labels differ by more than the
    observer (``"PHSO dt = 0.2 ms"``), one per such variant; else the
    observer's own (:data:`OBSERVER_STYLES`). Calling it with the same label
    always gives the same style, so a series looks the same in every panel.
    """

    def __init__(self) -> None:
        self._colors: dict[str, Any] = {}
        self._variants: dict[str, tuple[Any, str]] = {}

    def __call__(self, label: str, *, lw: float = 1.0) -> dict[str, Any]:
        """``color``, ``ls``, ``lw`` and ``marker`` for ``label``.

        ``lw`` scales the observer's width (or is the width of a series without one).
        """
        s = series_style(label)
        if s["color"] is None:
            n = len(self._colors)
            s["color"] = self._colors.setdefault(label, FALLBACK_COLORS[n % len(FALLBACK_COLORS)])
        if s["ls"] is None:
            m = _OBSERVER.search(label)
            variant = _variant(label)
            if variant or m is None:
                n = len(self._variants)
                s["ls"], marker = self._variants.setdefault(variant, _FALLBACK_STYLES[n % 4])
            else:
                s["ls"], marker = OBSERVER_STYLES[m.group(1).upper()], "o"
            s["marker"] = s["marker"] or marker
        s["marker"] = s["marker"] or "o"
        s["lw"] = lw * (s["lw"] / 1.4 if s["lw"] is not None else 1.0)
        return s

    def line(self, label: str, *, lw: float = 1.0) -> dict[str, Any]:
        """Keyword arguments of ``Axes.plot`` for a line (no marker)."""
        s = self(label, lw=lw)
        return {"color": s["color"], "ls": s["ls"], "lw": s["lw"]}

    def points(self, label: str) -> dict[str, Any]:
        """Keyword arguments of ``Axes.plot`` for open markers only (pole plots)."""
        s = self(label)
        return {"color": s["color"], "ls": "", "marker": s["marker"], "mfc": "none"}


def new_figure(nrows: int, ncols: int, *, figsize: tuple[float, float], **kw: Any):
    """A constrained-layout Figure (no pyplot) and its ``(nrows, ncols)`` array of Axes."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    return fig, axes


def legend(ax: Any, *, outside: bool = True, fontsize: float = 8, **kw: Any) -> Any:
    """The axes' legend: to the right of the data (``outside``) or where it hides least."""
    if outside:
        kw = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0, **kw}
    else:
        kw = {"loc": "best", **kw}
    return ax.legend(fontsize=fontsize, **kw)


_SUPERSCRIPTS = str.maketrans(
    "0123456789-+", "\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079\u207b\u207a"
)
_MATHDEFAULT = re.compile(r"^\$\\mathdefault\{(.*)\}\$$")
_POWER = re.compile(r"\^\{([0-9+-]+)\}")


def plain_tick_label(label: str) -> str:
    """A log-axis tick label of matplotlib's mathtext form as the same text in plain Unicode.

    ``$\\mathdefault{10^{-3}}$`` becomes ``10⁻³``, ``$\\mathdefault{2\\times10^{3}}$``
    ``2×10³`` and ``$\\mathdefault{-1}$`` ``−1`` (the minus sign mathtext draws). Any other
    label, or one with markup left after that, is returned unchanged.
    """
    m = _MATHDEFAULT.match(label)
    if m is None:
        return label
    body = _POWER.sub(lambda p: p.group(1).translate(_SUPERSCRIPTS), m.group(1))
    body = body.replace("\\times", "\u00d7")
    if any(c in body for c in "\\{}$^_"):
        return label
    return body.replace("-", "\u2212")


def plain_log_ticks(fig: Any) -> None:
    """Label the log and symlog axes of ``fig`` in plain text (:func:`plain_tick_label`).

    The same labels without mathtext, whose parser costs about 20 ms a label (0.4 s a
    report). matplotlib's log formatters are given a subclass that only rewrites the
    label, so their locator settings (``labelOnlyBase``, sub-labels, ``linthresh``) stay.
    """
    from matplotlib.ticker import LogFormatterSciNotation

    plain = _plain_formatter_class()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            for fmt in (axis.get_major_formatter(), axis.get_minor_formatter()):
                if type(fmt) is LogFormatterSciNotation:
                    fmt.__class__ = plain


@functools.cache
def _plain_formatter_class() -> type:
    """The formatter class, defined on first use (matplotlib is imported only then)."""
    from matplotlib.ticker import LogFormatterSciNotation

    class PlainLogFormatter(LogFormatterSciNotation):
        """:class:`~matplotlib.ticker.LogFormatterSciNotation` in plain Unicode text."""

        def __call__(self, x: float, pos: int | None = None) -> str:
            return plain_tick_label(super().__call__(x, pos))

    return PlainLogFormatter
