"""Figures of the identification report (matplotlib imported inside the functions)."""

from __future__ import annotations

import numpy as np

from .styles import new_figure

__all__ = ["plot_fit_time", "plot_fit_loop", "plot_residuals"]


def plot_fit_time(traces: dict[str, np.ndarray], *, title: str = "", length_unit: str = "um"):
    """Measured and model displacement over time, one column per record (training records
    first: ``t``, ``r2_t``, ...; then validation: ``val_t``, ``val2_t``, ...)."""
    sets = [("training", "")]
    for role, pre in (("training", "r{}_"), ("validation", "val{}_")):
        for k in range(2 if role == "training" else 1, 100):
            key = pre.format("" if k == 1 else k)
            if key + "t" not in traces:
                break
            label = role if k == 1 and role == "validation" else f"{role} {k}"
            sets.append((label, key))
    fig, axes = new_figure(2, len(sets), figsize=(5.5 * len(sets), 5.2), sharex="col")
    for j, (label, pre) in enumerate(sets):
        t, y, ym = traces[pre + "t"], traces[pre + "y"], traces[pre + "y_model"]
        ax = axes[0, j]
        ax.plot(t, y, color="black", lw=0.9, label="measured")
        ax.plot(t, ym, color="tab:blue", lw=0.9, ls="--", label="model")
        ax.set_ylabel(f"y ({length_unit})")
        ax.set_title(f"{label} record" + (f": {title}" if title and j == 0 else ""))
        ax.legend(loc="best", fontsize=8)
        ax = axes[1, j]
        ax.plot(t, y - ym, color="tab:red", lw=0.6, label="residual")
        ax.set_ylabel(f"measured - model ({length_unit})")
        ax.set_xlabel("t (s)")
        ax.legend(loc="best", fontsize=8)
    return fig, axes


def plot_fit_loop(traces: dict[str, np.ndarray], *, length_unit: str = "um", input_unit: str = "V"):
    """The hysteresis loop: input against displacement, measured and model."""
    fig, axes = new_figure(1, 1, figsize=(5.5, 4.4))
    ax = axes[0, 0]
    ax.plot(traces["u"], traces["y"], color="black", lw=0.6, label="measured")
    ax.plot(traces["u"], traces["y_model"], color="tab:blue", lw=0.6, ls="--", label="model")
    ax.set_xlabel(f"u ({input_unit})")
    ax.set_ylabel(f"y ({length_unit})")
    ax.set_title("hysteresis loop (training record)")
    ax.legend(loc="best", fontsize=8)
    return fig, axes


def plot_residuals(residual: np.ndarray, dt: float, *, max_lag: int = 200, length_unit: str = "um"):
    """Residual autocorrelation (with the +-2/sqrt(N) band of white noise) and spectrum."""
    r = np.asarray(residual, float) - np.mean(residual)
    n = r.size
    spec = np.fft.rfft(r, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec))[:n]
    acf = acf / acf[0] if acf[0] > 0 else acf
    lags = np.arange(min(max_lag, n - 1) + 1)
    fig, axes = new_figure(1, 2, figsize=(11, 3.8))
    ax = axes[0, 0]
    ax.plot(lags * dt * 1e3, acf[lags], color="tab:red", lw=0.9, label="residual")
    band = 2 / np.sqrt(n)
    ax.axhline(band, color="grey", ls=":", label="+-2/sqrt(N): white noise")
    ax.axhline(-band, color="grey", ls=":")
    ax.legend(loc="best", fontsize=8)
    ax.set_xlabel("lag (ms)")
    ax.set_ylabel("residual autocorrelation")
    ax = axes[0, 1]
    freqs = np.fft.rfftfreq(n, dt)
    psd = np.abs(np.fft.rfft(r * np.hanning(n))) ** 2 * dt / n
    ax.semilogy(freqs[1:], psd[1:] + 1e-300, color="tab:red", lw=0.6, label="residual")
    ax.legend(loc="best", fontsize=8)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"residual PSD ({length_unit}^2/Hz)")
    return fig, axes
