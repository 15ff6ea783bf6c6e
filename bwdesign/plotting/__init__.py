"""Plotting: the only bwdesign code that uses matplotlib, imported inside functions.

It imports nothing from bwdesign, so every layer may call it (inside a function).
"""

from .figures import plot_estimation_errors, plot_observer_states, save_figure

__all__ = ["save_figure", "plot_observer_states", "plot_estimation_errors"]
