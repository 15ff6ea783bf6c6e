"""Figures a person reads: a legend on every panel, one style per series, small errors visible.

Checked on the Axes the plotting functions return, with synthetic runs (no
simulation: each test builds its figures in well under a second).
"""

from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba

from bwdesign.plotting import figures
from bwdesign.plotting.identification import plot_fit_loop, plot_fit_time, plot_residuals
from bwdesign.plotting.styles import (
    FALLBACK_COLORS,
    GAIN_SET_COLORS,
    LAW_COLORS,
    OBSERVER_COLORS,
    Styler,
    series_style,
)
from bwdesign.plotting.sweep import plot_sweep_histograms

#: The report's six runs, as tracking_runs labels them.
LABELS = [f"{o} ({law})" for law in ("eq. 12", "digital tuning") for o in ("PHSO", "ESO", "PHDO")]
#: Peak tracking error of each (um): 60-um eq. 12 loops, a 0.25-um ESO, 0.009-um PHSO/PHDO.
PEAKS = [65.0, 66.0, 65.0, 0.009, 0.25, 0.009]


def _run(i: int, peak: float, *, observer: str = "phso", n: int = 500, est: float = 0.1):
    t = np.linspace(0.0, 1.0, n)
    xd = 100.0 + 80.0 * np.sin(2 * np.pi * 2 * t)
    e = peak * np.sin(2 * np.pi * 4 * t + 0.3 * i)
    x = np.column_stack([xd + e, np.gradient(xd + e, t), 0.5 * np.sin(2 * np.pi * 2 * t)])
    xhat = x + est * np.column_stack([np.exp(-5 * t)] * 3)
    return SimpleNamespace(
        t=t,
        x=x,
        xhat=xhat,
        x_d=xd,
        e=e,
        u=60.0 + 50.0 * np.sin(2 * np.pi * 2 * t),
        window=(0.5, 1.0),
        length_unit="um",
        settings={"input_unit": "V", "observer": observer},
        metrics=SimpleNamespace(maxe=abs(peak), me=abs(peak) / 2, rmse=abs(peak) / 3),
        stable=True,
        status="ok",
    )


RUNS = {label: _run(i, p, observer=label.split()[0].lower()) for i, (label, p) in
        enumerate(zip(LABELS, PEAKS, strict=True))}  # fmt: skip


def _estimation_curves(runs):
    panels = {"x1": "|x1hat - x1| (um)", "x2": "|x2hat - x2| (um/s)", "x3": "|x3hat - x3| (um)"}
    curves = {}
    for label, r in runs.items():
        err = r.xhat - r.x
        if label.startswith(("PHSO", "PHDO")):
            err = np.zeros_like(err)  # exact on the nominal plant, as in the report
        for i, panel in enumerate(panels):
            curves[f"{panel} | {label}"] = (r.t, err[:, i])
    return curves, panels


def _builders():
    curves, panels = _estimation_curves(RUNS)
    pole = SimpleNamespace(poles=np.array([0.9 + 0.05j, 0.9 - 0.05j, 0.5]))
    bode = SimpleNamespace(
        omega=np.logspace(0, 4, 50), magnitude=np.logspace(-2, -5, 50), peak=1e-2, omega_peak=1.0
    )
    sweep = SimpleNamespace(
        deltas=np.linspace(-0.1, 0.1, 5),
        max_real_part=-np.linspace(5, 1, 5),
        gain_margin_db=np.linspace(10, 5, 5),
        phase_margin=np.linspace(60, 40, 5),
        parameter="a1",
    )
    states = {k: RUNS[f"{k} (eq. 12)"].xhat for k in ("PHSO", "ESO")}
    fit = {"t": RUNS[LABELS[0]].t, "y": RUNS[LABELS[0]].x[:, 0], "u": RUNS[LABELS[0]].u}
    fit["y_model"] = fit["y"] + 0.01
    table = {
        "observer": np.array(["phso", "eso", "phdo"] * 20),
        "stable": np.ones(60, dtype=bool),
        **{m: np.linspace(0.1, 1.0, 60) for m in ("me", "maxe", "rmse")},
    }
    return {
        "tracking": lambda: figures.plot_tracking_comparison(RUNS),
        "estimation errors (stacked)": lambda: figures.plot_estimation_errors(
            curves, ylabel=panels, stack=True
        ),
        "estimation errors (row)": lambda: figures.plot_estimation_errors(curves),
        "observer states": lambda: figures.plot_observer_states(
            RUNS[LABELS[0]].t, RUNS[LABELS[0]].x, states
        ),
        "simulation": lambda: figures.plot_simulation(RUNS[LABELS[0]]),
        "peaking": lambda: figures.plot_peaking(
            {"PHSO": RUNS[LABELS[0]]}, {"PHSO": RUNS[LABELS[3]]}
        ),
        "loop poles": lambda: figures.plot_loop_poles(
            {"eq. 12 sampled": pole, "digital tuning": pole}
        ),
        "mismatch sweep": lambda: figures.plot_mismatch_sweep({"digital tuning": sweep}),
        "error poles": lambda: figures.plot_error_poles(
            {"configured, k = 0": pole.poles, "synthesised, k = 0": pole.poles}
        ),
        "hysteresis bode": lambda: figures.plot_hysteresis_bode(
            {"configured": bode, "synthesised": bode}, lipschitz_coeff=0.4, udot_max=400.0
        ),
        "sweep histograms": lambda: plot_sweep_histograms(table),
        "fit time": lambda: plot_fit_time(fit),
        "fit loop": lambda: plot_fit_loop(fit),
        "residuals": lambda: plot_residuals(fit["y"] - fit["y_model"] + RUNS[LABELS[0]].e, 1e-3),
    }


def _has_data(ax) -> bool:
    return any(len(ln.get_xdata()) for ln in ax.get_lines()) or bool(ax.patches)


@pytest.mark.parametrize("name", list(_builders()))
def test_every_panel_with_data_has_a_legend(name):
    fig, axes = _builders()[name]()
    panels = [ax for ax in np.ravel(axes) if _has_data(ax)]
    assert panels, name
    missing = [ax.get_title() or ax.get_ylabel() for ax in panels if ax.get_legend() is None]
    assert not missing, f"{name}: panels without a legend: {missing}"


def _styles(fig, labels):
    out: dict[str, set] = {}
    for ax in fig.axes:
        for ln in ax.get_lines():
            label = ln.get_label().split(":")[0]
            if label in labels:
                out.setdefault(label, set()).add((to_rgba(ln.get_color()), ln.get_linestyle()))
    return out


def test_a_series_keeps_one_colour_and_line_style_in_every_panel_and_figure():
    curves, panels = _estimation_curves(RUNS)
    tracking, _ = figures.plot_tracking_comparison(RUNS)
    errors, _ = figures.plot_estimation_errors(curves, ylabel=panels, stack=True)
    a, b = _styles(tracking, LABELS), _styles(errors, LABELS)
    assert set(a) == set(b) == set(LABELS)
    for label in LABELS:
        assert len(a[label] | b[label]) == 1, (label, a[label] | b[label])
    looks = [next(iter(a[label])) for label in LABELS]
    assert len(set(looks)) == len(LABELS), "two series share a colour and line style"
    # the observer picks the colour, the law the line style
    assert a["PHSO (eq. 12)"] != a["PHSO (digital tuning)"]
    assert {c for c, _ in a["PHSO (eq. 12)"]} == {c for c, _ in a["PHSO (digital tuning)"]}
    assert {s for _, s in a["PHSO (eq. 12)"]} == {s for _, s in a["ESO (eq. 12)"]}


def test_sub_micrometre_errors_get_their_own_axis():
    fig, axes = figures.plot_tracking_comparison(RUNS)
    # output, three error panels (65 um, 0.25 um, 0.009 um), input
    assert axes.shape == (5, 1)
    where = {}
    for i, ax in enumerate(axes[1:4, 0]):
        for ln in ax.get_lines():
            where[ln.get_label()] = i
    assert where["PHSO (eq. 12)"] == where["ESO (eq. 12)"] != where["PHSO (digital tuning)"]
    assert where["ESO (digital tuning)"] not in (
        where["PHSO (eq. 12)"],
        where["PHSO (digital tuning)"],
    )
    small = axes[1 + where["PHSO (digital tuning)"], 0]
    lo, hi = small.get_ylim()
    assert hi - lo < 0.1  # the 0.009-um error fills its axis instead of a flat line at 0
    # errors of one size stay on one axis
    same = {k: RUNS[k] for k in LABELS[:3]}
    _, axes = figures.plot_tracking_comparison(same)
    assert axes.shape == (3, 1)


def test_estimation_errors_one_axis_per_state_legend_outside_the_data():
    curves, panels = _estimation_curves(RUNS)
    fig, axes = figures.plot_estimation_errors(curves, ylabel=panels, stack=True, decades=12)
    assert axes.shape == (3, 1)
    assert [ax.get_ylabel() for ax in axes[:, 0]] == list(panels.values())
    a0, a1 = axes[0, 0], axes[1, 0]
    assert not a0.get_shared_y_axes().joined(a0, a1)  # um and um/s: no shared axis
    FigureCanvasAgg(fig).draw()
    for ax in axes[:, 0]:
        box, leg = ax.get_window_extent(), ax.get_legend().get_window_extent()
        assert leg.x0 >= box.x1, "legend drawn over the data"
        texts = [t.get_text() for t in ax.get_legend().get_texts()]
        assert "PHSO (eq. 12): 0 throughout" in texts  # an exact zero is said, not drawn at a floor
        assert not any(
            len(ln.get_xdata()) for ln in ax.get_lines() if ln.get_label().startswith("PHSO")
        )


def test_styles_by_words():
    s = series_style("PHSO (eq. 12)")
    assert (s["color"], s["ls"]) == (OBSERVER_COLORS["PHSO"], "--")
    assert series_style("PHSO (digital tuning)")["ls"] == "-"
    assert series_style("PHDO (eq. 12)")["color"] == OBSERVER_COLORS["PHDO"]
    assert series_style("eq. 12 sampled")["color"] == LAW_COLORS["eq. 12"]
    assert series_style("configured, k = 164")["color"] == GAIN_SET_COLORS["configured"]
    reserved = {*OBSERVER_COLORS.values(), *LAW_COLORS.values(), *GAIN_SET_COLORS.values()}
    assert not reserved & set(FALLBACK_COLORS)
    sty = Styler()
    a, b = sty("paper constants + observer"), sty("paper constants, true-state feedback")
    assert a["color"] != b["color"] and a["ls"] != b["ls"]
    assert sty("paper constants + observer") == a  # the same label, the same look
    # runs of one observer that differ by something else get a line style each
    assert sty("PHSO dt = 0.2 ms")["ls"] != sty("PHSO dt = 0.05 ms")["ls"]
    assert sty("PHSO dt = 0.2 ms")["ls"] == sty("ESO dt = 0.2 ms")["ls"]


def test_a_run_that_diverged_does_not_set_the_span():
    """The span is the first bounded run's window; a diverged run is named with its time."""
    bad = _run(0, 5.0)
    keep = bad.t <= 0.1
    bad = SimpleNamespace(**{**vars(bad), "metrics": None, "stable": False, "window": (0.08, 0.1)})
    for k in ("t", "x", "xhat", "x_d", "e", "u"):
        setattr(bad, k, getattr(bad, k)[keep])
    fig, axes = figures.plot_tracking_comparison(
        {"PHSO (eq. 12)": bad, "PHSO (digital tuning)": RUNS[LABELS[3]]}
    )
    assert axes[-1, 0].get_xlim()[0] > 0.4  # the bounded run's window (0.5 .. 1 s)
    texts = [t.get_text() for t in axes[0, 0].get_legend().get_texts()]
    assert f"PHSO (eq. 12): diverged at t = {bad.t[-1]:.3g} s" in texts
