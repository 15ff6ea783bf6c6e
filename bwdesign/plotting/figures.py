"""Plotting: the only bwdesign module that uses matplotlib, imported inside functions.

Every function builds a :class:`matplotlib.figure.Figure` directly (no pyplot,
no global state, Agg rendering for files) and returns ``(fig, axes)``; the
caller saves it with ``fig.savefig(path)`` or :func:`save_figure`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["save_figure", "plot_observer_states", "plot_estimation_errors"]

# consistent colours (and, in state plots, line styles) per estimator
_COLORS = {"true": "black", "PHSO": "tab:blue", "ESO": "tab:orange", "UKF": "tab:green"}
_STYLES = {"PHSO": "--", "ESO": "-.", "UKF": ":"}


def _figure(nrows: int, ncols: int, *, figsize: tuple[float, float], **kw: Any):
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    return fig, axes


def save_figure(fig: Any, path: Any, *, dpi: int = 120) -> None:
    """Write ``fig`` to ``path`` (format from the suffix, e.g. PNG via Agg)."""
    fig.savefig(path, dpi=dpi)


def _state_labels(length_unit: str) -> list[str]:
    return [
        f"x1 displacement ({length_unit})",
        f"x2 velocity ({length_unit}/s)",
        f"x3 hysteresis ({length_unit})",
    ]


def plot_observer_states(
    t: np.ndarray,
    truth: np.ndarray,
    estimates: dict[str, np.ndarray],
    *,
    t_zoom: float | None = None,
    title: str = "",
    length_unit: str = "um",
    floor: float = 1e-16,
):
    """True and estimated states (left) and the estimation error (right).

    The layout of the paper's Figures 1 and 2 (one row per state) with a
    second column for ``|x_hat - x|`` on a log scale over the whole run.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times (s).
    truth : array_like, shape (N, 3)
        True states.
    estimates : dict of str to array_like, shape (N, 3)
        Estimates by label (``"PHSO"``, ``"ESO"``, ``"UKF"`` get fixed colours).
    t_zoom : float, optional
        Right end (s) of the left column's time axis (default: whole run). The
        left column's y-range is fitted to the true state over
        ``[t_zoom/20, t_zoom]`` with a margin of 1.5 ranges on either side, so
        a large initial transient is clipped rather than flattening the plot.
    title : str
    length_unit : str
        Unit of x1 and x3.
    floor : float
        Errors are drawn as ``max(|e|, floor * range)`` so exact zeros show on
        the log axis (relative to each state's range).

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (3, 2)
    """
    t = np.asarray(t, dtype=float)
    truth = np.asarray(truth, dtype=float)
    fig, axes = _figure(3, 2, figsize=(11.0, 8.0))
    labels = _state_labels(length_unit)
    t_end = t_zoom if t_zoom is not None else float(t[-1])
    zoom = t <= t_end
    fit = zoom & (t >= t_end / 20)
    for i in range(3):
        ax, ax_e = axes[i, 0], axes[i, 1]
        ax.plot(t[zoom], truth[zoom, i], color=_COLORS["true"], lw=2.2, label="true")
        rng = float(np.ptp(truth[:, i])) or 1.0
        for name, est in estimates.items():
            est = np.asarray(est, dtype=float)
            c = _COLORS.get(name)
            ls = _STYLES.get(name, "--")
            ax.plot(t[zoom], est[zoom, i], color=c, lw=1.2, ls=ls, label=name)
            e = np.maximum(np.abs(est[:, i] - truth[:, i]), floor * rng)
            ax_e.semilogy(t, e, color=c, lw=0.8, label=name)
        if np.any(fit):
            lo, hi = float(truth[fit, i].min()), float(truth[fit, i].max())
            span = (hi - lo) or max(abs(hi), 1.0)
            ax.set_ylim(lo - 1.5 * span, hi + 1.5 * span)
        ax.set_ylabel(labels[i])
        ax_e.set_ylabel(f"|error| ({labels[i].split('(')[-1]}")
        ax.grid(True, alpha=0.3)
        ax_e.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize=8)
    axes[0, 1].legend(loc="best", fontsize=8)
    axes[2, 0].set_xlabel("t (s)")
    axes[2, 1].set_xlabel("t (s)")
    axes[0, 0].set_title("states" + (f" (first {t_zoom:g} s)" if t_zoom else ""))
    axes[0, 1].set_title("estimation error")
    if title:
        fig.suptitle(title)
    return fig, axes


def plot_estimation_errors(
    curves: dict[str, tuple[np.ndarray, np.ndarray]],
    *,
    title: str = "",
    ylabel: str = "|error|",
    panels: list[str] | None = None,
    floor: float = 1e-18,
):
    """Absolute estimation errors on a log scale, one panel per group.

    Parameters
    ----------
    curves : dict of str to (t, e)
        Label -> (times in s, error). A label of the form ``"panel | line"``
        puts the line in that panel. The line's first word picks the colour
        (``PHSO``, ``ESO``, ``UKF``) and the rest its line style, so e.g.
        ``"PHSO dt = 0.2 ms"`` and ``"ESO dt = 0.2 ms"`` share a style.
    title, ylabel : str
    panels : list of str, optional
        Panel order (default: order of first appearance).
    floor : float
        Lower clip of the drawn ``|e|``.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (1, n_panels)
    """
    groups: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    for label, (t, e) in curves.items():
        panel, _, line = label.partition(" | ")
        if not line:
            panel, line = "", label
        groups.setdefault(panel, []).append((line, np.asarray(t), np.asarray(e)))
    order = panels or list(groups)
    fig, axes = _figure(1, len(order), figsize=(max(5.5 * len(order), 9.0), 4.0), sharey=True)
    styles: dict[str, str] = {}  # line style per variant (the text after the estimator name)
    for ax, panel in zip(axes[0], order, strict=True):
        for line, t, e in groups[panel]:
            name, _, variant = line.partition(" ")
            ls = styles.setdefault(variant, ("-", "--", ":", "-.")[len(styles) % 4])
            ax.semilogy(
                t, np.maximum(np.abs(e), floor), lw=0.8, color=_COLORS.get(name), ls=ls, label=line
            )
        ax.set_title(panel)
        ax.set_xlabel("t (s)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[0, 0].set_ylabel(ylabel)
    if title:
        fig.suptitle(title)
    return fig, axes


# -- tracking loop (bwdesign.simulate, bwdesign.control) ------------------------------

__all__ += [
    "plot_simulation",
    "plot_tracking_comparison",
    "plot_peaking",
    "plot_loop_poles",
    "plot_mismatch_sweep",
]


def _input_unit(result: Any) -> str:
    """The input unit a simulation result records (``settings["input_unit"]``, default V)."""
    return getattr(result, "settings", {}).get("input_unit", "V")


def _track_color(label: str) -> Any:
    for key, c in _COLORS.items():
        if key != "true" and key in label.upper():
            return c
    return None


def plot_simulation(result: Any, *, title: str = "", t_range: tuple[float, float] | None = None):
    """One closed-loop run: tracking, error, input and estimation error.

    Parameters
    ----------
    result : bwdesign.simulate.SimulationResult
    title : str
    t_range : (float, float), optional
        Time span shown (s); default the whole run.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (4, 1)
    """
    t = np.asarray(result.t)
    sel = np.ones_like(t, dtype=bool)
    if t_range is not None:
        sel = (t >= t_range[0]) & (t <= t_range[1])
    lu = result.length_unit
    fig, axes = _figure(4, 1, figsize=(9.0, 9.0), sharex=True)
    a = axes[:, 0]
    a[0].plot(t[sel], result.x_d[sel], color="black", lw=1.5, label="x_d")
    a[0].plot(t[sel], result.x[sel, 0], color="tab:blue", lw=1.0, ls="--", label="x1")
    a[0].set_ylabel(f"position ({lu})")
    a[0].legend(loc="best", fontsize=8)
    a[1].plot(t[sel], result.e[sel], color="tab:red", lw=0.8)
    a[1].set_ylabel(f"e = x1 - x_d ({lu})")
    if result.metrics is not None:
        w0, w1 = result.window
        a[1].axvspan(w0, w1, color="0.9", zorder=0, label="metrics window")
        m = result.metrics
        a[1].set_title(
            f"MAXE {m.maxe:.4g}, ME {m.me:.4g}, RMSE {m.rmse:.4g} {lu} (shaded window)",
            fontsize=9,
        )
    a[2].plot(t[sel], result.u[sel], color="tab:green", lw=0.8)
    a[2].set_ylabel(f"u ({_input_unit(result)})")
    for i, name in enumerate(("x1", "x2", "x3")):
        d = result.xhat[sel, i] - result.x[sel, i]
        scale = float(np.max(np.abs(d))) or 1.0
        a[3].plot(t[sel], d / scale, lw=0.7, label=f"{name} (max {scale:.3g})")
    a[3].set_ylabel("estimation error / max")
    a[3].legend(loc="best", fontsize=7)
    a[3].set_xlabel("t (s)")
    for ax in a:
        ax.grid(True, alpha=0.3)
    if not result.stable:
        a[0].set_title(f"UNSTABLE: {result.status}", color="red", fontsize=9)
    if title:
        fig.suptitle(title)
    return fig, axes


def plot_tracking_comparison(
    results: dict[str, Any],
    *,
    title: str = "",
    t_range: tuple[float, float] | None = None,
    show_input: bool = True,
):
    """Tracking with several loops, as in the paper's Figures 3-5 and 7-8.

    Panels: (a) desired and achieved output, (b) tracking error, and, with
    ``show_input``, (c) control input.

    Parameters
    ----------
    results : dict of str to SimulationResult
        Label -> run (labels containing "PHSO", "ESO", "UKF" get the package colours).
    title : str
    t_range : (float, float), optional
        Span shown (s); default the metrics window of the first run.
    show_input : bool

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (2 or 3, 1)
    """
    first = next(iter(results.values()))
    if t_range is None:
        t_range = first.window
    n = 3 if show_input else 2
    fig, axes = _figure(n, 1, figsize=(9.0, 2.6 * n + 0.6), sharex=True)
    a = axes[:, 0]
    lu = first.length_unit
    t0 = np.asarray(first.t)
    s0 = (t0 >= t_range[0]) & (t0 <= t_range[1])
    a[0].plot(t0[s0], first.x_d[s0], color="black", lw=2.0, label="desired")
    styles = ("--", "-.", ":", "-")
    for i, (label, r) in enumerate(results.items()):
        t = np.asarray(r.t)
        s = (t >= t_range[0]) & (t <= t_range[1])
        c = _track_color(label)
        ls = styles[i % len(styles)]
        a[0].plot(t[s], r.x[s, 0], color=c, lw=1.1, ls=ls, label=label)
        a[1].plot(t[s], r.e[s], color=c, lw=0.9, ls=ls if i else "-", label=label)
        if show_input:
            a[2].plot(t[s], r.u[s], color=c, lw=0.9, ls=ls, label=label)
    a[0].set_ylabel(f"position ({lu})")
    a[1].set_ylabel(f"tracking error ({lu})")
    a[0].legend(loc="best", fontsize=8)
    a[1].legend(loc="best", fontsize=8)
    if show_input:
        a[2].set_ylabel(f"control input u ({_input_unit(first)})")
    a[-1].set_xlabel("t (s)")
    for tag, ax in zip("abc", a, strict=False):
        ax.grid(True, alpha=0.3)
        ax.set_title(f"({tag})", loc="left", fontsize=9)
    if title:
        fig.suptitle(title)
    return fig, axes


def plot_peaking(
    before: dict[str, Any],
    after: dict[str, Any],
    *,
    title: str = "",
    t_range: tuple[float, float] | None = None,
    labels: tuple[str, str] = ("before", "after"),
):
    """Step response without and with the anti-peaking remedy, side by side.

    Rows: output and reference, control input, ``|x3hat - x3|`` (log scale).

    Parameters
    ----------
    before, after : dict of str to SimulationResult
        Runs by observer label.
    title : str
    t_range : (float, float), optional
        Span shown (s).
    labels : (str, str)
        Column titles.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (3, 2)
    """
    fig, axes = _figure(3, 2, figsize=(12.0, 8.5), sharex=True)
    for col, (runs, head) in enumerate(((before, labels[0]), (after, labels[1]))):
        lu = "um"
        first = True
        for label, r in runs.items():
            lu = r.length_unit
            t = np.asarray(r.t)
            s = (
                np.ones_like(t, dtype=bool)
                if t_range is None
                else ((t >= t_range[0]) & (t <= t_range[1]))
            )
            c = _track_color(label)
            if first:
                axes[0, col].plot(t[s], r.x_d[s], color="black", lw=1.8, label="x_d")
                first = False
            tag = "" if r.stable else " (diverged)"
            axes[0, col].plot(t[s], r.x[s, 0], color=c, lw=1.0, label=label + tag)
            axes[1, col].plot(t[s], r.u[s], color=c, lw=0.9, label=label)
            err = np.maximum(np.abs(r.xhat[s, 2] - r.x[s, 2]), 1e-12)
            axes[2, col].semilogy(t[s], err, color=c, lw=0.8, label=label)
        axes[0, col].set_title(head, fontsize=10)
        axes[0, col].set_ylabel(f"x1, x_d ({lu})")
        axes[1, col].set_ylabel(f"u ({_input_unit(next(iter(runs.values()), None))})")
        axes[2, col].set_ylabel(f"|x3hat - x3| ({lu})")
        axes[2, col].set_xlabel("t (s)")
        for ax in axes[:, col]:
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(loc="best", fontsize=7)
    if title:
        fig.suptitle(title)
    return fig, axes


def plot_loop_poles(analyses: dict[str, Any], *, title: str = ""):
    """Closed-loop poles of sampled loops in the z-plane (with the unit circle).

    Parameters
    ----------
    analyses : dict of str to bwdesign.control.LoopAnalysis
        Sampled analyses (``dt`` set) by label.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (1, 2)
        Whole plane, and a zoom near z = 1.
    """
    fig, axes = _figure(1, 2, figsize=(11.0, 5.0))
    th = np.linspace(0, 2 * np.pi, 400)
    markers = ("x", "o", "+", "s", "^", "d")
    for ax in axes[0]:
        ax.plot(np.cos(th), np.sin(th), color="0.6", lw=0.8)
        for i, (label, a) in enumerate(analyses.items()):
            z = np.asarray(a.poles)
            ax.plot(
                z.real,
                z.imag,
                ls="",
                marker=markers[i % len(markers)],
                ms=7,
                mfc="none",
                label=label,
            )
        ax.set_aspect("equal")
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("Re z")
    axes[0, 0].set_ylabel("Im z")
    axes[0, 0].set_title("closed-loop poles", fontsize=10)
    axes[0, 1].set_aspect("auto")
    axes[0, 1].set_xlim(0.9, 1.01)
    axes[0, 1].set_ylim(-0.1, 0.1)
    axes[0, 1].set_title("zoom near z = 1", fontsize=10)
    axes[0, 0].legend(loc="lower left", fontsize=7)
    if title:
        fig.suptitle(title)
    return fig, axes


def plot_mismatch_sweep(sweeps: dict[str, Any], *, title: str = ""):
    """Stability and margins against a relative parameter error.

    Parameters
    ----------
    sweeps : dict of str to bwdesign.control.MismatchSweep

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (1, 3)
        Slowest decay rate, gain margin, phase margin against delta (%).
    """
    fig, axes = _figure(1, 3, figsize=(13.0, 4.0), sharex=True)
    for label, sw in sweeps.items():
        d = 100 * np.asarray(sw.deltas)
        axes[0, 0].plot(d, -np.asarray(sw.max_real_part), marker="o", ms=3, label=label)
        axes[0, 1].plot(d, sw.gain_margin_db, marker="o", ms=3, label=label)
        axes[0, 2].plot(d, sw.phase_margin, marker="o", ms=3, label=label)
    axes[0, 0].axhline(0.0, color="red", lw=0.8)
    axes[0, 0].set_yscale("symlog", linthresh=1.0)
    axes[0, 0].set_ylabel("slowest decay rate -max Re s (1/s)")
    axes[0, 1].set_ylabel("gain margin (dB)")
    axes[0, 2].set_ylabel("phase margin (deg)")
    param = next(iter(sweeps.values())).parameter
    for ax in axes[0]:
        ax.set_xlabel(f"{param} error delta (%)")
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize=7)
    if title:
        fig.suptitle(title)
    return fig, axes


# -- certificates and linear analysis (bwdesign.report) -----------------------------

__all__ += ["plot_error_poles", "plot_hysteresis_bode"]


def plot_error_poles(poles: dict[str, np.ndarray], *, title: str = ""):
    """Observer error poles in the s-plane.

    Parameters
    ----------
    poles : dict of str to complex ndarray
        Label -> eigenvalues (1/s).

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (1, 1)
    """
    fig, axes = _figure(1, 1, figsize=(7.0, 5.0))
    ax = axes[0, 0]
    markers = ("x", "o", "+", "s", "^", "d")
    for i, (label, p) in enumerate(poles.items()):
        p = np.asarray(p)
        ax.plot(
            p.real, p.imag, ls="", marker=markers[i % len(markers)], ms=8, mfc="none", label=label
        )
    ax.set_xscale("symlog", linthresh=1.0)
    ax.axvline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel("Re s (1/s, symlog)")
    ax.set_ylabel("Im s (rad/s)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    return fig, axes


def plot_hysteresis_bode(
    bodes: dict[str, Any],
    *,
    lipschitz_coeff: float,
    udot_max: float,
    title: str = "",
    input_unit: str = "V",
):
    """Bode magnitude from the hysteresis error to eps3, with the lipschitz bound 1/L.

    Parameters
    ----------
    bodes : dict of str to bwdesign.certify.linear.HysteresisBode
    lipschitz_coeff : float
        ``|beta| + |gamma|`` (1/input unit).
    udot_max : float
        Envelope (input unit/s); the line ``1/L`` with ``L = lipschitz_coeff * udot_max``
        is what the peak must stay below for the lipschitz tier.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (1, 1)
    """
    fig, axes = _figure(1, 1, figsize=(8.0, 4.5))
    ax = axes[0, 0]
    for label, b in bodes.items():
        ax.loglog(b.omega, b.magnitude, lw=1.2, label=f"{label} (peak {b.peak:.3g} s)")
        ax.plot([b.omega_peak], [b.peak], marker="o", ms=5, color=ax.lines[-1].get_color())
    bound = 1.0 / (lipschitz_coeff * udot_max)
    label = f"1/L at |u'| = {udot_max:.4g} {input_unit}/s"
    ax.axhline(bound, color="tab:red", ls="--", lw=1.0, label=label)
    ax.set_xlabel("omega (rad/s)")
    ax.set_ylabel("|e3' (j omega I - A)^-1 e3| (s)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    return fig, axes
