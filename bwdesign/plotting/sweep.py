"""Figures of a Monte Carlo sweep: metric histograms per observer."""

from __future__ import annotations

from typing import Any

import numpy as np

from .styles import legend, new_figure, series_style

__all__ = ["plot_sweep_histograms"]


def plot_sweep_histograms(
    table: dict[str, np.ndarray],
    *,
    metrics=("me", "maxe", "rmse"),
    length_unit: str = "um",
    title: str = "",
) -> tuple[Any, Any]:
    """Histograms of the tracking metrics of the stable scenarios, one colour per observer.

    Parameters
    ----------
    table : dict of arrays
        Sweep columns (``observer``, ``stable`` and the metric columns).
    metrics : sequence of str
    length_unit : str
    title : str

    Returns
    -------
    fig, axes
    """
    fig, axes = new_figure(1, len(metrics), figsize=(4.0 * len(metrics), 3.4))
    observers = list(dict.fromkeys(table["observer"].tolist()))
    for ax, m in zip(axes[0], metrics, strict=True):
        vals = [table[m][(table["observer"] == o) & table["stable"]] for o in observers]
        finite = np.concatenate([v[np.isfinite(v)] for v in vals]) if vals else np.array([])
        if finite.size == 0:
            ax.text(0.5, 0.5, "no stable scenario", ha="center", transform=ax.transAxes)
            continue
        lo, hi = float(finite.min()), float(finite.max())
        bins = np.linspace(lo, hi if hi > lo else lo + 1e-12, 31)
        for o, v in zip(observers, vals, strict=True):
            ax.hist(
                v, bins=bins, alpha=0.55, color=series_style(o.upper())["color"], label=o.upper()
            )
        ax.set_xlabel(f"{m.upper()} ({length_unit})")
        ax.set_ylabel("scenarios")
        legend(ax, outside=False)
    if title:
        fig.suptitle(title)
    return fig, axes
