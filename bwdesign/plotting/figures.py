"""Plotting: the only bwdesign module that uses matplotlib, imported inside functions.

Every function builds a :class:`matplotlib.figure.Figure` directly (no pyplot,
no global state, Agg rendering for files) and returns ``(fig, axes)``; the
caller saves it with ``fig.savefig(path)`` or :func:`save_figure`. Every panel
with data has a legend, and a series keeps one colour and line style in every
panel and every figure (:mod:`bwdesign.plotting.styles`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .styles import BOUND_COLOR, Styler, legend, new_figure, plain_log_ticks

__all__ = ["save_figure", "plot_observer_states", "plot_estimation_errors"]


def save_figure(fig: Any, path: Any, *, dpi: int = 120) -> None:
    """Write ``fig`` to ``path`` (format from the suffix, e.g. PNG via Agg), its log axes
    labelled in plain text (:func:`~bwdesign.plotting.styles.plain_log_ticks`)."""
    plain_log_ticks(fig)
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
        Estimates by label (styled by :mod:`bwdesign.plotting.styles`: ``"PHSO"``,
        ``"ESO"``, ``"PHDO"``, ``"UKF"`` have fixed colours).
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
        the log axis (relative to each state's range); an error that is 0
        throughout is not drawn and its legend entry says so.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (3, 2)
    """
    t = np.asarray(t, dtype=float)
    truth = np.asarray(truth, dtype=float)
    fig, axes = new_figure(3, 2, figsize=(11.0, 8.0))
    sty = Styler()
    labels = _state_labels(length_unit)
    t_end = t_zoom if t_zoom is not None else float(t[-1])
    zoom = t <= t_end
    fit = zoom & (t >= t_end / 20)
    for i in range(3):
        ax, ax_e = axes[i, 0], axes[i, 1]
        ax.plot(t[zoom], truth[zoom, i], label="true", **sty.line("true", lw=1.1))
        rng = float(np.ptp(truth[:, i])) or 1.0
        for name, est in estimates.items():
            est = np.asarray(est, dtype=float)
            ax.plot(t[zoom], est[zoom, i], label=name, **sty.line(name))
            _error_line(ax_e, t, est[:, i] - truth[:, i], floor * rng, name, sty.line(name))
        if np.any(fit):
            lo, hi = float(truth[fit, i].min()), float(truth[fit, i].max())
            span = (hi - lo) or max(abs(hi), 1.0)
            ax.set_ylim(lo - 1.5 * span, hi + 1.5 * span)
        ax.set_ylabel(labels[i])
        ax_e.set_ylabel(f"|error| ({labels[i].split('(')[-1]}")
        ax.grid(True, alpha=0.3)
        ax_e.grid(True, which="both", alpha=0.3)
        legend(ax, outside=False, fontsize=7)
        legend(ax_e, outside=False, fontsize=7)
    axes[2, 0].set_xlabel("t (s)")
    axes[2, 1].set_xlabel("t (s)")
    axes[0, 0].set_title("states" + (f" (first {t_zoom:g} s)" if t_zoom else ""))
    axes[0, 1].set_title("estimation error")
    if title:
        fig.suptitle(title)
    return fig, axes


def _error_line(ax: Any, t: np.ndarray, e: np.ndarray, floor: float, label: str, kw: dict) -> None:
    """``|e|`` on a log axis, clipped at ``floor``; an error 0 throughout only in the legend."""
    e = np.abs(np.asarray(e, dtype=float))
    if np.all(e == 0):
        ax.plot([], [], label=f"{label}: 0 throughout", **kw)
        return
    ax.semilogy(t, np.maximum(e, floor), label=label, **kw)


def plot_estimation_errors(
    curves: dict[str, tuple[np.ndarray, np.ndarray]],
    *,
    title: str = "",
    ylabel: str | dict[str, str] = "|error|",
    panels: list[str] | None = None,
    floor: float = 1e-18,
    stack: bool = False,
    decades: float | None = None,
):
    """Absolute estimation errors on a log scale, one panel per group.

    Parameters
    ----------
    curves : dict of str to (t, e)
        Label -> (times in s, error). A label of the form ``"panel | line"``
        puts the line in that panel. The line's words pick its style
        (:mod:`bwdesign.plotting.styles`: the observer its colour, the law
        ``eq. 12``/``digital tuning`` or else the rest of the label its line
        style), so e.g. ``"PHSO dt = 0.2 ms"`` and ``"ESO dt = 0.2 ms"`` share a style.
    title : str
    ylabel : str or dict of str to str
        One label for all panels (which then share their y axis), or one per
        panel (each panel its own y axis: states with different units).
    panels : list of str, optional
        Panel order (default: order of first appearance).
    floor : float
        Lower clip of the drawn ``|e|``; an error 0 throughout is not drawn
        and its legend entry says so.
    stack : bool
        Panels one above the other (full width each) instead of side by side.
    decades : float, optional
        Show at most this many decades below each panel's largest error
        (default: down to ``floor``).

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (1, n_panels), or (n_panels, 1) with ``stack``
        Each panel has its legend to the right of the data.
    """
    groups: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    for label, (t, e) in curves.items():
        panel, _, line = label.partition(" | ")
        if not line:
            panel, line = "", label
        groups.setdefault(panel, []).append((line, np.asarray(t), np.asarray(e)))
    order = panels or list(groups)
    shared = isinstance(ylabel, str)
    n = len(order)
    if stack:
        fig, axes = new_figure(n, 1, figsize=(10.0, 2.4 * n + 0.8), sharex=True, sharey=shared)
    else:
        fig, axes = new_figure(1, n, figsize=(max(5.5 * n, 9.0), 4.0), sharey=shared)
    sty = Styler()
    for ax, panel in zip(axes.flat, order, strict=True):
        top = 0.0
        for line, t, e in groups[panel]:
            _error_line(ax, t, e, floor, line, sty.line(line, lw=0.9))
            top = max(top, float(np.nanmax(np.abs(e), initial=0.0)))
        if decades is not None and top > 0 and not shared:
            ax.set_ylim(bottom=max(floor, top * 10.0**-decades))
        ax.set_title(panel, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        legend(ax)
        if not shared:
            ax.set_ylabel(ylabel.get(panel, "|error|"))
    for ax in axes[-1] if stack else axes[0]:
        ax.set_xlabel("t (s)")
    if shared:
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


def plot_simulation(result: Any, *, title: str = "", t_range: tuple[float, float] | None = None):
    """One closed-loop run: tracking, error, input and estimation error.

    The run's traces have its observer's colour (:mod:`bwdesign.plotting.styles`).

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
    obs = str(getattr(result, "settings", {}).get("observer") or "run").upper()
    sty = Styler()
    run = sty.line(obs)
    fig, axes = new_figure(4, 1, figsize=(10.0, 9.0), sharex=True)
    a = axes[:, 0]
    a[0].plot(t[sel], result.x_d[sel], label="x_d", **sty.line("x_d", lw=0.75))
    a[0].plot(t[sel], result.x[sel, 0], label=f"x1 ({obs})", **run)
    a[0].set_ylabel(f"position ({lu})")
    a[1].plot(t[sel], result.e[sel], label=f"x1 - x_d ({obs})", **run)
    a[1].set_ylabel(f"tracking error ({lu})")
    if result.metrics is not None:
        w0, w1 = result.window
        a[1].axvspan(w0, w1, color="0.9", zorder=0, label="metrics window")
        m = result.metrics
        a[1].set_title(
            f"MAXE {m.maxe:.4g}, ME {m.me:.4g}, RMSE {m.rmse:.4g} {lu} (shaded window)",
            fontsize=9,
        )
    a[2].plot(t[sel], result.u[sel], label=f"u ({obs})", **run)
    a[2].set_ylabel(f"u ({_input_unit(result)})")
    for i, (name, ls) in enumerate(zip(("x1", "x2", "x3"), ("-", "--", ":"), strict=True)):
        d = result.xhat[sel, i] - result.x[sel, i]
        scale = float(np.max(np.abs(d))) if d.size else 0.0
        if scale == 0.0:
            a[3].plot([], [], color=run["color"], ls=ls, label=f"{name}: 0 throughout")
            continue
        a[3].plot(
            t[sel], d / scale, color=run["color"], ls=ls, lw=0.8, label=f"{name} / {scale:.3g}"
        )
    a[3].set_ylabel("estimation error / its max")
    a[3].set_xlabel("t (s)")
    for ax in a:
        ax.grid(True, alpha=0.3)
        legend(ax)
    if not result.stable:
        a[0].set_title(f"UNSTABLE: {result.status}", color=BOUND_COLOR, fontsize=9)
    if title:
        fig.suptitle(title)
    return fig, axes


def _magnitude_groups(peaks: dict[str, float], ratio: float, most: int) -> list[list[str]]:
    """Labels grouped by the size of their peak, largest first.

    Sorted by peak, the list is cut where one peak is more than ``ratio`` times
    the next (at the ``most - 1`` largest such gaps), so each group fits one
    linear axis. A peak that is not finite goes with the largest. Within a
    group the labels keep the order of ``peaks``.
    """
    order = sorted(peaks, key=lambda k: -peaks[k] if np.isfinite(peaks[k]) else -np.inf)
    gaps = []
    for i in range(len(order) - 1):
        hi, lo = peaks[order[i]], peaks[order[i + 1]]
        if np.isfinite(hi) and hi > 0 and (lo <= 0 or hi / lo > ratio):
            gaps.append((hi / lo if lo > 0 else np.inf, i + 1))
    cuts = sorted(i for _, i in sorted(gaps, reverse=True)[: most - 1])
    groups = [set(order[a:b]) for a, b in zip([0, *cuts], [*cuts, len(order)], strict=True)]
    return [[k for k in peaks if k in g] for g in groups]


def plot_tracking_comparison(
    results: dict[str, Any],
    *,
    title: str = "",
    t_range: tuple[float, float] | None = None,
    show_input: bool = True,
    split_ratio: float = 10.0,
):
    """Tracking with several loops, as in the paper's Figures 3-5 and 7-8.

    Panels: (a) desired and achieved output, (b) tracking error, and, with
    ``show_input``, a last panel with the control input. Errors whose peaks
    differ by more than ``split_ratio`` get panels of their own (at most three,
    largest first), so a sub-micrometre error is not drawn as a flat line
    beside a 60 um one. Every panel has its legend to the right of the data. A
    run that diverged before the span is named in the legend with the time it
    diverged.

    Parameters
    ----------
    results : dict of str to SimulationResult
        Label -> run (styled by :mod:`bwdesign.plotting.styles`: the observer in
        the label picks the colour, the law ``eq. 12``/``digital tuning`` the line style).
    title : str
    t_range : (float, float), optional
        Span shown (s); default the metrics window of the first run that has one.
    show_input : bool
    split_ratio : float
        Peak ratio above which errors go to separate panels.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (n, 1)
        Output, one to three error panels, then the input (with ``show_input``).
    """
    first = next(iter(results.values()))
    if t_range is None:  # a run that diverged has no metrics window of its own
        t_range = next(
            (r.window for r in results.values() if getattr(r, "metrics", 1) is not None),
            first.window,
        )
    sel = {}
    for label, r in results.items():
        t = np.asarray(r.t)
        sel[label] = (t >= t_range[0]) & (t <= t_range[1])
    # a run with no sample in the span (it diverged before) is named in the legend only
    shown = [label for label in results if np.any(sel[label])]
    peaks = {}
    for label in shown:
        e = np.abs(np.asarray(results[label].e)[sel[label]])
        peaks[label] = float(np.max(e)) if np.all(np.isfinite(e)) else np.nan
    groups = _magnitude_groups(peaks, split_ratio, 3) or [[]]
    n = 1 + len(groups) + int(show_input)
    fig, axes = new_figure(n, 1, figsize=(10.0, 2.3 * n + 0.8), sharex=True)
    a = axes[:, 0]
    sty = Styler()
    lu = first.length_unit
    ref = next(iter(shown), next(iter(results)))
    t0, s0 = np.asarray(results[ref].t), sel[ref]
    # the reference thin and on top: loops that track it exactly do not hide it
    a[0].plot(
        t0[s0], results[ref].x_d[s0], label="desired", zorder=3, **sty.line("desired", lw=0.6)
    )
    for label, r in results.items():
        t, s = np.asarray(r.t), sel[label]
        name = label if label in shown else f"{label}: diverged at t = {t[-1]:.3g} s"
        a[0].plot(t[s], r.x[s, 0], label=name, **sty.line(label))
        if show_input:
            a[-1].plot(t[s], r.u[s], label=name, **sty.line(label))
    for ax, group in zip(a[1:], groups, strict=False):
        for label in group:
            t, s = np.asarray(results[label].t), sel[label]
            ax.plot(t[s], results[label].e[s], label=label, **sty.line(label))
        ax.set_ylabel(f"tracking error ({lu})")
    a[0].set_ylabel(f"position ({lu})")
    if show_input:
        a[-1].set_ylabel(f"control input u ({_input_unit(first)})")
    a[-1].set_xlabel("t (s)")
    heads = ["output"] + ["tracking error"] * len(groups) + ["input"] * int(show_input)
    for i, (tag, ax) in enumerate(zip("abcdef", a, strict=False)):
        head = heads[i]
        if head == "tracking error" and len(groups) > 1:
            g = groups[i - 1]
            head += f", peaks {_peak_text([peaks[k] for k in g])} {lu}"
        ax.set_title(f"({tag}) {head}", loc="left", fontsize=9)
        ax.grid(True, alpha=0.3)
        legend(ax)
    if title:
        fig.suptitle(title)
    return fig, axes


def _peak_text(values: list[float]) -> str:
    """``0.0091 .. 0.25`` (or one number) for the peaks of a panel."""
    finite = [v for v in values if np.isfinite(v)]
    if not finite:
        return "not finite"
    lo, hi = min(finite), max(finite)
    return f"{hi:.2g}" if f"{lo:.2g}" == f"{hi:.2g}" else f"{lo:.2g} .. {hi:.2g}"


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
    fig, axes = new_figure(3, 2, figsize=(12.0, 8.5), sharex=True)
    sty = Styler()
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
            kw = sty.line(label)
            if first:
                axes[0, col].plot(t[s], r.x_d[s], label="x_d", **sty.line("x_d", lw=0.9))
                first = False
            tag = "" if r.stable else " (diverged)"
            axes[0, col].plot(t[s], r.x[s, 0], label=label + tag, **kw)
            axes[1, col].plot(t[s], r.u[s], label=label, **kw)
            err = np.maximum(np.abs(r.xhat[s, 2] - r.x[s, 2]), 1e-12)
            axes[2, col].semilogy(t[s], err, label=label, **kw)
        axes[0, col].set_title(head, fontsize=10)
        axes[0, col].set_ylabel(f"x1, x_d ({lu})")
        axes[1, col].set_ylabel(f"u ({_input_unit(next(iter(runs.values()), None))})")
        axes[2, col].set_ylabel(f"|x3hat - x3| ({lu})")
        axes[2, col].set_xlabel("t (s)")
        for ax in axes[:, col]:
            ax.grid(True, which="both", alpha=0.3)
            legend(ax, outside=False, fontsize=7)
    if title:
        fig.suptitle(title)
    return fig, axes


def plot_loop_poles(analyses: dict[str, Any], *, title: str = ""):
    """Closed-loop poles of sampled loops in the z-plane (with the unit circle).

    Parameters
    ----------
    analyses : dict of str to bwdesign.control.LoopAnalysis
        Sampled analyses (``dt`` set) by label (the law in the label, ``eq. 12``
        or ``digital tuning``, picks colour and marker).

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (1, 2)
        Whole plane, and a zoom near z = 1; each with its legend.
    """
    fig, axes = new_figure(1, 2, figsize=(11.0, 5.0))
    sty = Styler()
    th = np.linspace(0, 2 * np.pi, 400)
    for ax in axes[0]:
        ax.plot(np.cos(th), np.sin(th), color="0.6", lw=0.8, label="unit circle")
        for label, a in analyses.items():
            z = np.asarray(a.poles)
            ax.plot(z.real, z.imag, ms=7, label=label, **sty.points(label))
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("Re z")
    axes[0, 0].set_aspect("equal")
    axes[0, 0].set_ylabel("Im z")
    axes[0, 0].set_title("closed-loop poles", fontsize=10)
    axes[0, 1].set_xlim(0.9, 1.01)
    axes[0, 1].set_ylim(-0.1, 0.1)
    axes[0, 1].set_title("zoom near z = 1", fontsize=10)
    legend(axes[0, 0], outside=False, loc="lower left", fontsize=7)
    legend(axes[0, 1], outside=False, loc="lower left", fontsize=7)
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
        Slowest decay rate, gain margin, phase margin against delta (%); each with its legend.
    """
    fig, axes = new_figure(1, 3, figsize=(13.0, 4.0), sharex=True)
    sty = Styler()
    for label, sw in sweeps.items():
        d = 100 * np.asarray(sw.deltas)
        s = sty(label)
        kw = {"color": s["color"], "ls": s["ls"], "marker": s["marker"], "ms": 3, "label": label}
        axes[0, 0].plot(d, -np.asarray(sw.max_real_part), **kw)
        axes[0, 1].plot(d, sw.gain_margin_db, **kw)
        axes[0, 2].plot(d, sw.phase_margin, **kw)
    axes[0, 0].axhline(0.0, color=BOUND_COLOR, lw=0.8, label="stability limit")
    axes[0, 0].set_yscale("symlog", linthresh=1.0)
    axes[0, 0].set_ylabel("slowest decay rate -max Re s (1/s)")
    axes[0, 1].set_ylabel("gain margin (dB)")
    axes[0, 2].set_ylabel("phase margin (deg)")
    param = next(iter(sweeps.values())).parameter
    for ax in axes[0]:
        ax.set_xlabel(f"{param} error delta (%)")
        ax.grid(True, alpha=0.3)
        legend(ax, outside=False, fontsize=7)
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
        Label -> eigenvalues (1/s). The gain set in the label (``configured``,
        ``synthesised``) picks the colour, the rest (e.g. ``k = 0``) the marker.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (1, 1)
    """
    fig, axes = new_figure(1, 1, figsize=(8.0, 5.0))
    sty = Styler()
    ax = axes[0, 0]
    for label, p in poles.items():
        p = np.asarray(p)
        ax.plot(p.real, p.imag, ms=8, label=label, **sty.points(label))
    ax.set_xscale("symlog", linthresh=1.0)
    ax.axvline(0.0, color="0.5", lw=0.8, label="imaginary axis")
    ax.set_xlabel("Re s (1/s, symlog)")
    ax.set_ylabel("Im s (rad/s)")
    ax.grid(True, alpha=0.3)
    legend(ax)
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
        By gain-set label (``configured``, ``synthesised``: the colour).
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
    fig, axes = new_figure(1, 1, figsize=(8.0, 4.5))
    sty = Styler()
    ax = axes[0, 0]
    for label, b in bodes.items():
        kw = sty.line(label, lw=1.2)
        ax.loglog(b.omega, b.magnitude, label=f"{label} (peak {b.peak:.3g} s)", **kw)
        ax.plot([b.omega_peak], [b.peak], marker="o", ms=5, color=kw["color"])
    bound = 1.0 / (lipschitz_coeff * udot_max)
    label = f"1/L at |u'| = {udot_max:.4g} {input_unit}/s"
    ax.axhline(bound, color=BOUND_COLOR, ls="--", lw=1.0, label=label)
    ax.set_xlabel("omega (rad/s)")
    ax.set_ylabel("|e3' (j omega I - A)^-1 e3| (s)")
    ax.grid(True, which="both", alpha=0.3)
    legend(ax, outside=False)
    if title:
        ax.set_title(title)
    return fig, axes
