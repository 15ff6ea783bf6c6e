"""The paper's Tables 1 and 2 reproduced side by side, the digital-loop analysis, and peaking.

Usage::

    .venv/bin/python analysis/paper_tables.py [--out reports/paper] [--jobs 2]

Sections of the generated report (``paper_tables.md``, ``paper_tables.json``,
PNG figures in ``--out``):

1. **Table 1** (paper Section 4.2): continuous-time loop
   (:func:`bwdesign.sim.simulate_continuous`, Radau) on
   ``paper_simulation_corrected`` with gains (80, 160, -640),
   lambda1 = 2.2e6, lambda2 = 80; references ``30 sin(2 pi f t - pi/2) + 30``
   at 1 and 20 Hz, and a triangle of the same amplitude, offset and phase at
   1 Hz (the paper does not give its frequency: our assumption). Plant and
   estimates start at 0.
2. **Digital loop** (paper Section 5 constants on ``paper_experiment`` at
   0.2 ms): poles, margins, a1-mismatch sensitivity, the predicted and the
   simulated steady-state error; and the digital tuning from
   :func:`bwdesign.design.digital_tuning`.
3. **Table 2** (Section 5): sampled loop at dt = 0.2 ms, sine
   ``80 sin(2 pi t) + 100`` and 1 Hz triangle 180 um peak to peak, offset
   100, with the paper's constants (eq. 12 as printed) and with the digital
   tuning; then the digital tuning under sensor noise and model mismatch.
4. **Peaking**: a step reference with and without the remedy.

Runs in about two minutes on two cores (the continuous runs and the long
runs go to a process pool of ``--jobs`` workers).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import math
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

import bwdesign
from bwdesign import (
    ClosedLoop,
    ContinuousSolver,
    ObserverSpec,
    Sine,
    Start,
    Step,
    Triangle,
    make_controller,
    preset,
)
from bwdesign.control.analysis import analyze_loop, mismatch_sweep
from bwdesign.design.tuning import digital_tuning, observer_gains
from bwdesign.model.params import BoucWenParams
from bwdesign.output.files import prepare_directory
from bwdesign.sim.closed_loop import simulate
from bwdesign.sim.continuous import simulate_continuous
from bwdesign.sim.result import SimulationResult

T0 = time.perf_counter()

# -- the paper's numbers (quoted from Tables 1 and 2; only ever used as "paper") ----
PAPER_T1 = {
    "1 Hz sine": {"ESO": (0.2406, 0.0516, 0.2078), "PHSO": (0.0219, 0.0053, 0.0098)},
    "20 Hz sine": {"ESO": (4.0237, 1.0313, 2.0451), "PHSO": (0.4043, 0.1051, 0.1554)},
    "triangle": {"ESO": (3.1032, 0.0623, 0.2431), "PHSO": (0.0639, 0.0082, 0.0145)},
}
PAPER_T2 = {
    "sine": {"ESO": (1.5619, 0.5915, 0.6646), "PHSO": (1.3960, 0.3178, 0.3804)},
    "triangle": {"ESO": (1.7983, 0.5286, 0.6583), "PHSO": (1.6593, 0.2976, 0.3764)},
}
CRITERIA = ("MAXE", "ME", "RMSE")

# -- settings ------------------------------------------------------------------------
SEC42 = dict(gains=(80.0, 160.0, -640.0), lambda1=2.2e6, lambda2=80.0)
SEC5 = dict(gains=(8.0, 64.0, -512.0), lambda1=1.0, lambda2=2.0)
DT = 2e-4
NOISE_STD = 0.02  # um: a capacitive sensor on a 200 um stage (0.01 % of range)
# V: an assumed amplifier range (the Table 2 references need up to ~135 V on this model)
U_LIMITS_EXP = (-30.0, 150.0)


def log(msg: str) -> None:
    print(f"[{time.perf_counter() - T0:6.1f} s] {msg}", file=sys.stderr, flush=True)


def metrics_tuple(r: SimulationResult) -> tuple[float, float, float] | None:
    if r.metrics is None:
        return None
    return (r.metrics.maxe, r.metrics.me, r.metrics.rmse)


def improvement(eso: float, phso: float) -> float:
    return 100.0 * (eso - phso) / eso if eso else math.nan


def make_loop(
    p: BoucWenParams,
    observer: str,
    *,
    gains: Any,
    lambda1: float,
    lambda2: float,
    dt: float | None = None,
    form: str = "continuous",
    integral_rate: float | None = None,
    u_limits: Any = None,
    hysteresis_jump: bool = False,
    delay: bool = False,
    start: Start | None = None,
) -> ClosedLoop:
    """``observer`` on ``gains`` (the PHDO on ``(l1, l2, 0, l3)`` of 3), eq. (12) in ``form``."""
    law = make_controller(
        p, lambda1, lambda2, form=form, dt=dt, integral_rate=integral_rate,
        u_limits=u_limits, hysteresis_jump=hysteresis_jump,
    )  # fmt: skip
    spec = ObserverSpec.of(observer, gains)
    return ClosedLoop(p, spec, law, dt=dt, delay=delay, start=start or Start())


# -- worker tasks (module level so the process pool can pickle them) ---------------
# A task names its plant, its reference, its loop (make_loop's keywords) and its run
# (the simulation's keywords; "true": the relative changes of the simulated plant).


def run_continuous(task: dict[str, Any]) -> SimulationResult:
    p = preset(task["plant"])
    loop = make_loop(p, **task["loop"])
    return simulate_continuous(loop, task["reference"], **task["run"])


def run_sampled(task: dict[str, Any]) -> SimulationResult:
    p = preset(task["plant"])
    run = dict(task["run"])
    true = run.pop("true", None)
    if true is not None:
        run["true_params"] = p.replace(**true)
    return simulate(make_loop(p, **task["loop"]), task["reference"], **run)


def run_task(task: dict[str, Any]) -> SimulationResult:
    return run_continuous(task) if task["kind"] == "continuous" else run_sampled(task)


# -- helpers for the Markdown ---------------------------------------------------------


def fmt(v: float | None, digits: int = 4) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    if v == 0:
        return "0"
    if abs(v) < 1e-3 or abs(v) >= 1e4:
        return f"{v:.2e}"
    return f"{v:.{digits}g}"


def fmt_pole(z: complex) -> str:
    z = complex(z)
    if abs(z.imag) < 1e-9 * max(1.0, abs(z)):
        return fmt(z.real, 4)
    return f"{fmt(z.real, 4)} {'+' if z.imag > 0 else '-'} {fmt(abs(z.imag), 4)}j"


def pct(v: float) -> str:
    if not math.isfinite(v):
        return "n/a"
    return f"{v:.2f} %" if v >= 0 else f"{v:.0f} % (ESO better)"


def side_by_side(rows: list[tuple[str, dict, dict]], ours_label: str) -> list[str]:
    """Markdown table: paper ESO | PHSO | impr. || ours ESO | PHSO | impr. | ratio ours/paper."""
    out = [
        f"| signal | criterion | paper ESO | paper PHSO | paper impr. | {ours_label} ESO | "
        f"{ours_label} PHSO | our impr. | ours/paper ESO | ours/paper PHSO |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, paper, ours in rows:
        for i, c in enumerate(CRITERIA):
            pe, pp = paper["ESO"][i], paper["PHSO"][i]
            oe = ours["ESO"][i] if ours["ESO"] else math.nan
            op = ours["PHSO"][i] if ours["PHSO"] else math.nan
            out.append(
                f"| {name if i == 0 else ''} | {c} (um) | {fmt(pe)} | {fmt(pp)} | "
                f"{pct(improvement(pe, pp))} | {fmt(oe)} | {fmt(op)} | {pct(improvement(oe, op))}"
                f" | {fmt(oe / pe, 3)} | {fmt(op / pp, 3)} |"
            )
    return out


def off_by_factor(rows: list[tuple[str, dict, dict]], factor: float = 2.0) -> list[str]:
    """Cells where ours and the paper's differ by more than ``factor``."""
    cells = []
    for name, paper, ours in rows:
        for obs in ("ESO", "PHSO"):
            if not ours[obs]:
                cells.append(f"{name} {obs}: our loop diverged")
                continue
            for i, c in enumerate(CRITERIA):
                ratio = ours[obs][i] / paper[obs][i]
                if not (1 / factor <= ratio <= factor):
                    cells.append(f"{name} {obs} {c} (x{ratio:.3g})")
    return cells


def save(fig: Any, path: Path) -> None:
    from bwdesign.plotting.figures import save_figure

    save_figure(fig, path)
    log(f"wrote {path.name}")


# -- the report ------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="reports/paper", help="output directory")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    args = ap.parse_args(argv)
    # through the output layer: a directory holding other files is refused, the old output
    # stays whole until the new one is complete
    target = prepare_directory(args.out, command="analysis paper_tables", what="--out")
    with target.stage() as stage:
        return _run(args, stage.root)


def _run(args: argparse.Namespace, out: Path) -> int:
    from bwdesign.plotting.figures import (
        plot_loop_poles,
        plot_mismatch_sweep,
        plot_peaking,
        plot_tracking_comparison,
    )

    sim = preset("paper_simulation_corrected")
    exp = preset("paper_experiment")
    doc: dict[str, Any] = {
        "generated_by": "analysis/paper_tables.py",
        "versions": {
            "bwdesign": bwdesign.__version__,
            "python": platform.python_version(),
            **{
                m: importlib.metadata.version(m)
                for m in ("numpy", "scipy", "control", "matplotlib")
            },
        },
    }
    md: list[str] = ["# Zhao et al. 2024, Tables 1 and 2: the paper's numbers beside ours", ""]
    md += [
        "Generated by `analysis/paper_tables.py`; do not edit. Versions: "
        + ", ".join(f"{k} {v}" for k, v in doc["versions"].items())
        + ".",
        "",
        "Metrics (paper): MAXE = max |e|, ME = mean |e|, RMSE, over the last two reference "
        "periods (steady state), in um. Improvement = (ESO - PHSO)/ESO. "
        "The paper's columns are quoted from its Tables 1 and 2.",
        "",
    ]

    # ---------------------------------------------------------------- task list
    refs1 = {
        "1 Hz sine": (Sine(amplitude=30, offset=30, frequency=1, phase=-math.pi / 2), 2.5),
        "20 Hz sine": (Sine(amplitude=30, offset=30, frequency=20, phase=-math.pi / 2), 0.3),
        "triangle": (Triangle(amplitude=30, offset=30, frequency=1, phase=-math.pi / 2), 2.5),
    }
    tasks: dict[tuple, dict] = {}
    for name, (ref, dur) in refs1.items():
        for obs in ("ESO", "PHSO"):
            tasks[("t1", name, obs)] = dict(
                kind="continuous",
                plant="paper_simulation_corrected",
                reference=ref,
                loop=dict(observer=obs.lower(), **SEC42),
                run=dict(duration=dur),
            )
    refs2 = {
        "sine": Sine(amplitude=80, offset=100, frequency=1),
        "triangle": Triangle(amplitude=90, offset=100, frequency=1),
    }
    # the paper's constants as printed: run long enough for the slowest sampled pole
    a_paper = analyze_loop(make_loop(exp, "phso", dt=DT, **SEC5))
    dur_paper = float(min(150.0, max(3.0, math.ceil(12.0 / a_paper.slowest_decay_rate))))
    a_paper_d = analyze_loop(make_loop(exp, "phso", dt=DT, form="discrete", **SEC5))
    dur_paper_d = float(min(150.0, max(3.0, math.ceil(12.0 / a_paper_d.slowest_decay_rate))))
    full_plus = dict(a1=exp.a1 * 1.02, a3=exp.a3 * 0.98, alpha=exp.alpha * 1.1,
                     beta=exp.beta * 0.9, gamma=exp.gamma * 1.1)  # fmt: skip
    full_minus = dict(a1=exp.a1 * 0.98, a3=exp.a3 * 1.02, alpha=exp.alpha * 0.9,
                      beta=exp.beta * 1.1, gamma=exp.gamma * 0.9)  # fmt: skip
    hyst_only = dict(alpha=exp.alpha * 1.1, beta=exp.beta * 0.9, gamma=exp.gamma * 1.1)
    for name, ref in refs2.items():
        for obs in ("ESO", "PHSO"):
            tasks[("t2paper", name, obs, "nominal")] = dict(
                kind="sampled",
                plant="paper_experiment",
                reference=ref,
                loop=dict(observer=obs.lower(), dt=DT, **SEC5),
                run=dict(duration=dur_paper),
            )
            tasks[("t2paper", name, obs, "noise+mismatch")] = dict(
                kind="sampled",
                plant="paper_experiment",
                reference=ref,
                loop=dict(observer=obs.lower(), dt=DT, **SEC5),
                run=dict(duration=dur_paper, noise_std=NOISE_STD, seed=2, true=full_plus),
            )
        tasks[("t2paper_discrete", name, "PHSO")] = dict(
            kind="sampled",
            plant="paper_experiment",
            reference=ref,
            loop=dict(observer="phso", dt=DT, form="discrete", **SEC5),
            run=dict(duration=dur_paper_d),
        )

    log(f"{len(tasks)} long runs on {args.jobs} worker(s)")
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        futures = {k: pool.submit(run_task, t) for k, t in tasks.items()}

        # -- while the pool works: the linear analysis and the digital tuning -------
        log("digital loop: analysis of the Section 5 constants")
        g5 = SEC5["gains"]
        l1, l2 = SEC5["lambda1"], SEC5["lambda2"]
        paper_loop = make_loop(exp, "phso", dt=DT, **SEC5)
        a_cont_design = analyze_loop(paper_loop.replace(dt=None))
        a_state = analyze_loop(paper_loop, estimator="state")
        deltas = np.array([-5, -2, -1, -0.5, -0.1, -0.01, 0, 0.01, 0.1, 0.5, 1, 2, 5]) / 100
        sw_paper = mismatch_sweep(paper_loop, deltas=deltas)
        sw_state = mismatch_sweep(paper_loop, deltas=deltas, estimator="state")
        log("digital tuning")
        tuning = digital_tuning(exp, DT)
        tk = tuning.controller_kwargs()
        tuned_loop = make_loop(exp, "phso", dt=DT, delay=True, **tuning.controller_kwargs())
        sw_tuned = mismatch_sweep(tuned_loop, deltas=deltas)
        a_tuned = tuning.nominal
        tuning_paper_gains = digital_tuning(exp, DT, gains=g5)

        # the digital tuning's runs are short: run them here
        log("Table 2 with the digital tuning")
        conditions = {
            "nominal": dict(),
            "noise": dict(noise_std=NOISE_STD, seed=1),
            "noise + hysteresis +-10 %": dict(noise_std=NOISE_STD, seed=1, true=hyst_only),
            "noise + full mismatch (+)": dict(noise_std=NOISE_STD, seed=1, true=full_plus),
            "noise + full mismatch (-)": dict(noise_std=NOISE_STD, seed=1, true=full_minus),
        }
        tuned: dict[tuple, SimulationResult] = {}
        for name, ref in refs2.items():
            for cond, extra in conditions.items():
                for obs in ("ESO", "PHSO", "PHDO"):
                    # each observer with the tuning's gains for it (PHDO: (l1, l2, 0, l3))
                    tko = tuning.controller_kwargs(observer=obs.lower())
                    tuned[(name, cond, obs)] = run_sampled(
                        dict(
                            plant="paper_experiment",
                            reference=ref,
                            loop=dict(observer=obs.lower(), dt=DT, delay=True, **tko),
                            run=dict(duration=3.0, **extra),
                        )
                    )

        log("peaking")
        peak = peaking_runs(exp, sim)
        log("waiting for the long runs")
        res = {k: f.result() for k, f in futures.items()}
    log("all runs done")

    # ---------------------------------------------------------------- Table 1
    rows1 = []
    for name in refs1:
        ours = {o: metrics_tuple(res[("t1", name, o)]) for o in ("ESO", "PHSO")}
        rows1.append((name, PAPER_T1[name], ours))
    md += [
        "## Table 1: Section 4.2, continuous-time simulation",
        "",
        "Plant `paper_simulation_corrected` (Section 4's parameters with beta = +1.3567: the "
        "sign correction is bwdesign's, the printed set is outside the bounded class), gains "
        "(80, 160, -640), lambda1 = 2.2e6, lambda2 = 80 1/s, continuous observers (eqs. 3, 21) "
        "and controller (eq. 12), integrated with Radau (rtol 1e-8, atol 1e-10 per state "
        "scale, max step = output spacing of 1/5000 period). u' is obtained by solving the "
        "implicit relation exactly (the law depends on x3hat, whose rate depends on u'); "
        "see `bwdesign.simulate`. Plant and estimates start at 0; references "
        "30 sin(2 pi f t - pi/2) + 30 um. **Assumption:** the triangle has the sine's "
        "amplitude, offset and phase and a frequency of 1 Hz (the paper does not state it); "
        "its sharp corners are treated as the paper's controller sees them (x_d'' = 0, the "
        "impulse dropped), with the hysteresis following the resulting jump of u exactly.",
        "",
        *side_by_side(rows1, "ours"),
        "",
    ]
    a42 = analyze_loop(make_loop(sim, "phso", **SEC42))
    md += [
        "Linear loop of this setting (`analyze_loop`, continuous): poles "
        + ", ".join(fmt_pole(z) for z in sorted(a42.poles, key=lambda z: z.real))
        + f" 1/s; gain margin {fmt(a42.gain_margin_db, 3)} dB, phase margin "
        f"{fmt(a42.phase_margin, 3)} deg at {fmt(a42.crossover, 4)} rad/s. It cannot be run "
        "digitally at any practical rate (lambda1 dt must stay well below 1: dt << 0.5 us).",
        "",
    ]
    doc["table1_loop"] = a42.to_dict()
    est1 = {
        name: {o: res[("t1", name, o)].estimation_rmse for o in ("ESO", "PHSO")} for name in refs1
    }
    off1 = off_by_factor(rows1)
    phso_rmse = max(res[("t1", n, "PHSO")].metrics.rmse for n in refs1)
    md += [
        "Estimation RMSE of x3 over the window (um): "
        + "; ".join(
            f"{n}: ESO {fmt(est1[n]['ESO'][2])}, PHSO {fmt(est1[n]['PHSO'][2])}" for n in refs1
        )
        + ".",
        "",
        "**Differences beyond a factor of 2** ("
        + (", ".join(off1) if off1 else "none")
        + "), and why:",
        "",
        f"- *PHSO, every row.* Our PHSO errors are at the level of the integrator's tolerance "
        f"(largest RMSE {fmt(phso_rmse)} um), orders of magnitude below the paper's. In an "
        "exact simulation the PHSO is an exact copy of the plant (the same Bouc-Wen model and "
        "parameters, and the same u'), so the estimation error obeys the observer's error "
        "dynamics with no forcing and decays at the observer's rate (slowest pole about -638 "
        "1/s for these gains) from whatever the initial error is; by the steady-state window "
        "it is zero to rounding, and so is the tracking error, which the law makes a function "
        "of the estimation error only. The paper's non-zero PHSO errors (0.005-0.1 um ME) must "
        "come from its numerical method, which it does not state (a fixed-step solver, or u' "
        "from a numerical derivative, would give exactly such a floor); we cannot reproduce an "
        "unstated discretisation, and the exact figure is the meaningful one.",
        "- *ESO.* The ESO treats x3 as constant, so its error is forced by x3' = phi(u', x3), "
        "which the continuous simulation reproduces without ambiguity; where our ESO numbers "
        "differ from the paper's by more than 2x the likely causes are the unstated details: "
        "initial state, window, solver, and for the triangle its frequency (assumed 1 Hz) and "
        "the treatment of its corners (the paper's MAXE of 3.1 um is a corner spike, whose "
        "height depends on how the solver meets the jump of x_d'). The RMSE of the paper's "
        "1 Hz ESO row (0.2078 um with ME 0.0516, ratio 4) suggests a window that includes "
        "part of the transient.",
        "- The direction of every comparison agrees: the PHSO beats the ESO on every "
        "criterion in every row, by more than the paper's 80-97 %.",
        "",
    ]
    for name, fname, fig_no in (
        ("1 Hz sine", "fig3_table1_sine_1hz.png", 3),
        ("20 Hz sine", "fig4_table1_sine_20hz.png", 4),
        ("triangle", "fig5_table1_triangle_1hz.png", 5),
    ):
        fig, _ = plot_tracking_comparison(
            {
                "ESO": res[("t1", name, "ESO")],
                "PHSO": res[("t1", name, "PHSO")],
            },
            title=f"Section 4.2, {name} (like the paper's Figure {fig_no}): steady-state window",
            show_input=False,
        )
        save(fig, out / fname)
        md.append(f"![Figure {fig_no} analogue]({fname})")
    md.append("")
    doc["table1"] = {
        "settings": {**SEC42, "plant": "paper_simulation_corrected", "triangle_frequency_hz": 1.0},
        "rows": {
            name: {
                "paper": PAPER_T1[name],
                "ours": {o: res[("t1", name, o)].to_dict() for o in ("ESO", "PHSO")},
            }
            for name in refs1
        },
        "beyond_factor_2": off1,
    }

    # ---------------------------------------------------------------- digital loop
    decay_rows = decay_check(exp, tuning)
    doc["decay_check"] = decay_rows
    amp = 80.0
    gains_text = ", ".join(f"{v:.6g}" for v in tuning.gains)
    g_cont = abs(a_paper.tracking_gain(1.0))
    g_disc = abs(a_paper_d.tracking_gain(1.0))
    r_pc = res[("t2paper", "sine", "PHSO", "nominal")]
    r_pd = res[("t2paper_discrete", "sine", "PHSO")]
    md += [
        "## The digital loop: are the Section 5 constants usable at 0.2 ms?",
        "",
        "Linear analysis (`bwdesign.control.analyze_loop`) of the loop the experiment ran: "
        "`paper_experiment`, observer gains (8, 64, -512) mapped to the sampled observer by "
        "pole matching, lambda1 = 1, lambda2 = 2, dt = 0.2 ms; exact ZOH plant with x3 "
        "held (the linear parts of the PHSO and ESO coincide); loop broken at the plant "
        "input for the margins.",
        "",
        "| loop | slowest pole (1/s) | spectral radius | gain margin (loop-gain interval) "
        "| phase margin | crossover | delay margin | abs(E/X_d) at 1 Hz |",
        "|---|---:|---:|---|---:|---:|---:|---:|",
    ]

    def loop_row(label, a):
        gm = a.gain_margin
        return (
            f"| {label} | {fmt(a.max_real_part)} | "
            f"{'-' if a.spectral_radius is None else f'{a.spectral_radius:.8f}'} | "
            f"{fmt(a.gain_margin_db, 3)} dB ({fmt(gm[0], 3)} .. {fmt(gm[1], 3)}) | "
            f"{fmt(a.phase_margin, 3)} deg | {fmt(a.crossover, 4)} rad/s | "
            f"{fmt(a.delay_margin * 1e3, 3)} ms | {fmt(abs(a.tracking_gain(1.0)), 3)} |"
        )

    md += [
        loop_row("continuous time (the design)", a_cont_design),
        loop_row("eq. 12 as printed, sampled at 0.2 ms", a_paper),
        loop_row("discrete form of eq. 12, same lambdas", a_paper_d),
        loop_row("eq. 12 with true states (no observer), 0.2 ms", a_state),
        loop_row(
            f"digital tuning (lambda = {tuning.lambda1:.4g}, integral {tuning.integral_rate:.4g},"
            " one-sample delay)",
            a_tuned,
        ),
        "",
        "Closed-loop poles (sampled, as continuous equivalents log(z)/dt, 1/s), eq. 12 as "
        "printed: "
        + ", ".join(fmt_pole(z) for z in sorted(a_paper.poles_s, key=lambda z: z.real))
        + "; digital tuning: "
        + ", ".join(fmt_pole(z) for z in sorted(a_tuned.poles_s, key=lambda z: z.real))
        + ".",
        "",
        "What this says:",
        "",
        f"- **The sampled loop is stable, but not the loop that was designed.** The design "
        f"puts the tracking-error poles at -1 and -2 1/s. Sampled with a zero-order hold, the "
        f"cancellation term a1 x1hat/a3 lags the spring force by dt/2 on average, which acts "
        f"as an extra velocity feedback a1 dt/2 = {exp.a1 * DT / 2:.3g} 1/s against a "
        f"designed lambda1 + lambda2 = 3 1/s. The error poles move to "
        f"{fmt(-a_paper.slowest_decay_rate, 3)} and about -18 1/s: a time constant of "
        f"{1 / a_paper.slowest_decay_rate:.3g} s, so the loop needs about a minute to settle.",
        f"- **The steady-state error is tens of micrometres.** The same ZOH lag is a force "
        f"proportional to the stage's velocity, which the slow loop hardly resists: the "
        f"linear loop predicts an error amplitude abs(E/X_d) x 80 um = {g_cont * amp:.3g} um "
        f"at 1 Hz (ME = 2/pi x amplitude = {2 / math.pi * g_cont * amp:.3g} um); "
        f"the simulation gives ME {fmt(r_pc.metrics.me)} um (PHSO, {dur_paper:g} s run, "
        f"window = last two periods). Even the discrete form of the same law (poles exactly "
        f"at exp(-dt), exp(-2 dt)) leaves {fmt(g_disc * amp, 3)} um predicted, "
        f"ME {fmt(r_pd.metrics.me)} um simulated ({dur_paper_d:g} s run): a loop with 1 1/s "
        "of bandwidth integrates every O(dt^3) residual of the sampled feedforward. "
        "The paper's experimental 0.3-0.6 um cannot have come from eq. (12) with these "
        "constants run as printed at 0.2 ms on this model; its implementation must have "
        "differed in a way the paper does not describe.",
        f"- **Margins: about {fmt(a_paper.gain_margin_db, 2)} dB and "
        f"{fmt(a_paper.phase_margin, 3)} deg**, set by the observer, not by lambda: with "
        "gains (8, 64, -512) the observer's poles are the lightly damped plant resonance "
        "(-31 +- 351j 1/s, damping 0.09) and -659 1/s, and the loop crosses over near "
        f"{fmt(a_paper.crossover, 3)} rad/s, right at that resonance. A loop gain "
        f"{100 * (a_paper.gain_margin[1] - 1):.0f} % above the model's (a3 underestimated by "
        "a third) destabilises it; lower gains are safe (the interval reaches 0).",
        f"- **a1 mismatch.** With true-state feedback the law cancels a1 x1 exactly only if "
        f"a1 is exact: it is stable for a1 errors in [{sw_state.interval[0]:.3g}, "
        f"{sw_state.interval[1]:.3g}] (relative), i.e. a 0.00125 % overestimate of a1 removes "
        f"all the loop's stiffness (lambda1 lambda2 / a1 = {l1 * l2 / exp.a1:.3g}). With the "
        f"observer in the loop the picture changes completely: stable for a1 errors in "
        f"[{sw_paper.interval[0]:.3g}, {sw_paper.interval[1]:.3g}] (upper end = search bound), "
        "with poles and margins barely moved over +-5 %. The observer's x3 estimate absorbs "
        "the model error (in the linear part both the ESO's and the PHSO's x3hat integrate "
        "the innovation), so a1 (x1hat + x3hat) equals the true a1 (x1 + x3) at low "
        "frequency: the observer acts as a disturbance observer. (For the PHSO the nonlinear "
        "hysteresis copy limits how far x3hat can go; see the mismatch table below.) The "
        "fear that a fraction of a percent of a1 error "
        "destabilises the loop is right for the law and wrong for the law with its observer; "
        "the a1 sensitivity that remains is the poor margin above.",
        "",
        "**Poles against simulation** (free decay from a 10 um offset with a 2 um initial "
        "estimation error, constant reference, PHSO; decay rate fitted to log|e|):",
        "",
        "| loop | slowest pole of the analysis (1/s) | simulated decay rate (1/s) | fit window |",
        "|---|---:|---:|---|",
        *[
            f"| {row['label']} | {fmt(row['predicted'], 4)} | {fmt(row['simulated'], 4)} | "
            f"{row['window'][0]:g}-{row['window'][1]:g} s |"
            for row in decay_rows
        ],
        "",
        "The linear analysis holds x3 (dh/du = 0). It is exact for the loop whose law "
        "cancels the hysteresis estimate *after* the jump that u_k causes "
        "(`hysteresis_jump=True`, the sampled counterpart of solving the implicit relation "
        "for u'). The plain sampled law cancels the pre-jump estimate one sample late. In a "
        "loop as weak as the paper's (stiffness lambda1 lambda2 = 2 1/s^2), that lag, acting "
        "through the hysteresis slope, moves the slowest pole by 10 % (slower); in the "
        "digital tuning it moves it by 5 % (faster), which does not matter.",
        "",
        "| a1 error | " + " | ".join(f"{100 * d:+.2g} %" for d in deltas) + " |",
        "|---|" + "---:|" * len(deltas),
        "| slowest decay rate, paper constants + observer (1/s) | "
        + " | ".join(fmt(-v, 3) for v in sw_paper.max_real_part)
        + " |",
        "| same, true-state feedback (1/s) | "
        + " | ".join(fmt(-v, 3) for v in sw_state.max_real_part)
        + " |",
        "| phase margin, paper constants + observer (deg) | "
        + " | ".join(fmt(v, 3) for v in sw_paper.phase_margin)
        + " |",
        "| slowest decay rate, digital tuning (1/s) | "
        + " | ".join(fmt(-v, 3) for v in sw_tuned.max_real_part)
        + " |",
        "| phase margin, digital tuning (deg) | "
        + " | ".join(fmt(v, 3) for v in sw_tuned.phase_margin)
        + " |",
        "",
        "(A negative decay rate is an unstable loop.)",
        "",
        "### Digital tuning (`bwdesign.design.digital_tuning(params, dt)`)",
        "",
        tuning.reasoning + ".",
        "",
        f"Result: lambda1 = lambda2 = {tuning.lambda1:.4g} 1/s, integral rate "
        f"{tuning.integral_rate:.4g} 1/s, observer gains ({gains_text})."
        f" Nominal margins {fmt(a_tuned.gain_margin_db, 3)} dB, {fmt(a_tuned.phase_margin, 3)} "
        f"deg at {fmt(a_tuned.crossover, 4)} rad/s, delay margin "
        f"{fmt(a_tuned.delay_margin / DT, 3)} samples; worst case over a1, a3 +-2 %: "
        f"{fmt(tuning.worst_gain_margin_db, 3)} dB, {fmt(tuning.worst_phase_margin, 3)} deg, "
        f"{fmt(tuning.worst_delay_margin / DT, 3)} samples. a1 stability interval "
        f"[{sw_tuned.interval[0]:.3g}, {sw_tuned.interval[1]:.3g}].",
        "",
        "Keeping the paper's observer gains (8, 64, -512) and tuning lambda alone cannot meet "
        f"the requirements: the best is lambda = {tuning_paper_gains.lambda1:.4g} with "
        f"{fmt(tuning_paper_gains.worst_gain_margin_db, 3)} dB and "
        f"{fmt(tuning_paper_gains.worst_phase_margin, 3)} deg worst case. The observer has "
        "to be re-tuned for the sample rate as well.",
        "",
    ]
    fig, _ = plot_loop_poles(
        {
            "eq. 12 as printed (paper constants)": a_paper,
            "discrete form, paper lambdas": a_paper_d,
            "digital tuning": a_tuned,
        },
        title="Sampled tracking loop at 0.2 ms on paper_experiment",
    )
    save(fig, out / "fig_digital_loop_poles.png")
    fig, _ = plot_mismatch_sweep(
        {
            "paper constants + observer": sw_paper,
            "paper constants, true-state feedback": sw_state,
            "digital tuning": sw_tuned,
        },
        title="Sampled loop against a relative a1 error (true a1 = (1 + delta) a1 model)",
    )
    save(fig, out / "fig_a1_mismatch.png")
    md += ["![poles](fig_digital_loop_poles.png)", "", "![a1 mismatch](fig_a1_mismatch.png)", ""]
    doc["digital_loop"] = {
        "paper_constants": {
            "as_printed": a_paper.to_dict(),
            "discrete_form": a_paper_d.to_dict(),
            "continuous_design": a_cont_design.to_dict(),
            "true_state_feedback": a_state.to_dict(),
            "tracking_gain_1hz": {"as_printed": g_cont, "discrete_form": g_disc},
            "a1_sweep": sw_paper.to_dict(),
            "a1_sweep_true_state": sw_state.to_dict(),
            "simulated_me_um": {"as_printed": r_pc.metrics.me, "discrete_form": r_pd.metrics.me},
        },
        "digital_tuning": tuning.to_dict(),
        "digital_tuning_a1_sweep": sw_tuned.to_dict(),
        "tuning_with_paper_gains": {
            "lambda": tuning_paper_gains.lambda1,
            "worst_gain_margin_db": tuning_paper_gains.worst_gain_margin_db,
            "worst_phase_margin_deg": tuning_paper_gains.worst_phase_margin,
            "met": tuning_paper_gains.met,
        },
    }

    # ---------------------------------------------------------------- Table 2
    rows2p, rows2t = [], []
    for name in refs2:
        rows2p.append(
            (
                name,
                PAPER_T2[name],
                {o: metrics_tuple(res[("t2paper", name, o, "nominal")]) for o in ("ESO", "PHSO")},
            )
        )
        rows2t.append(
            (
                name,
                PAPER_T2[name],
                {o: metrics_tuple(tuned[(name, "nominal", o)]) for o in ("ESO", "PHSO")},
            )
        )
    md += [
        "## Table 2: Section 5, the sampled loop on `paper_experiment`",
        "",
        "dt = 0.2 ms, exact ZOH plant, sampled observers. References: 80 sin(2 pi t) + 100 um "
        "and a 1 Hz triangle of 180 um peak to peak around 100 um (phase 0, sharp corners). "
        "Plant and estimates start at rest at 0 (the first samples are a transient; the "
        "window is the last two periods).",
        "",
        f"### With the paper's constants (gains 8, 64, -512; lambda1 = 1, lambda2 = 2; eq. 12 "
        f"as printed), nominal model, no noise, {dur_paper:g} s runs",
        "",
        *side_by_side(rows2p, "ours"),
        "",
        f"### With the digital tuning (discrete form, lambda = {tuning.lambda1:.4g}, integral "
        f"{tuning.integral_rate:.4g} 1/s, observer triple pole {tuning.observer_bandwidth:.4g} "
        "rad/s, one-sample computation delay), nominal model, no noise, 3 s runs",
        "",
        *side_by_side(rows2t, "ours"),
        "",
    ]
    off2p = off_by_factor(rows2p)
    off2t = off_by_factor(rows2t)
    md += [
        "**Differences beyond a factor of 2.** Paper constants: "
        + (", ".join(off2p) if off2p else "none")
        + ". Digital tuning: "
        + (", ".join(off2t) if off2t else "none")
        + ".",
        "",
        "- *Paper constants:* the errors are those of the slow, ZOH-shifted loop analysed "
        "above (tens of um, ESO and PHSO alike since both estimate the state well: the error "
        "is the controller's, not the observers'). The experiment's 0.3-1.8 um are not what "
        "eq. (12) with these constants gives at 0.2 ms on the identified model.",
        "- *Digital tuning, nominal:* the simulation has what the experiment lacked, an exact "
        "model and no noise, so its errors are far below the experiment's. The comparison "
        "with the experiment is the next table, which adds the two.",
        "",
    ]
    # Table 2b: noise and mismatch
    md += [
        "### The digital tuning under sensor noise and model mismatch",
        "",
        f"What the experiment had and a simulation lacks. Noise: white Gaussian, std "
        f"{NOISE_STD:g} um on y (a capacitive sensor on a 200 um stage; seeded). Mismatch "
        "(the true plant differs from the model used by observer and controller): "
        "*hysteresis +-10 %*: alpha +10 %, beta -10 %, gamma +10 % (Bouc-Wen shape "
        "parameters are the least well identified); *full (+)*: additionally a1 +2 %, "
        "a3 -2 % (static gain a3/a1 4 % low, a typical identification error of the linear "
        "part); *full (-)*: all signs reversed. The margins of the tuning were checked "
        "against the same a1, a3 corners.",
        "",
        "| signal | condition | ESO MAXE | ESO ME | ESO RMSE | PHSO MAXE | PHSO ME | PHSO RMSE "
        "| impr. ME | impr. RMSE | PHDO MAXE | PHDO ME | PHDO RMSE | PHDO ME / ESO "
        "| PHDO ME / PHSO |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    t2b = {}
    for name in refs2:
        for cond in conditions:
            e = tuned[(name, cond, "ESO")]
            p = tuned[(name, cond, "PHSO")]
            me = metrics_tuple(e)
            mp = metrics_tuple(p)
            md_ = metrics_tuple(tuned[(name, cond, "PHDO")])
            t2b[(name, cond)] = (me, mp)
            if me is None or mp is None or md_ is None:
                md.append(f"| {name} | {cond} | diverged | | | | | | | | | | | | |")
                continue
            md.append(
                f"| {name} | {cond} | {fmt(me[0])} | {fmt(me[1])} | {fmt(me[2])} | "
                f"{fmt(mp[0])} | {fmt(mp[1])} | {fmt(mp[2])} | {pct(improvement(me[1], mp[1]))} "
                f"| {pct(improvement(me[2], mp[2]))} | {fmt(md_[0])} | {fmt(md_[1])} "
                f"| {fmt(md_[2])} | {md_[1] / me[1]:.2f} | {md_[1] / mp[1]:.2f} |"
            )
    for name in refs2:
        cells = []
        for o in ("ESO", "PHSO"):
            r = res[("t2paper", name, o, "noise+mismatch")]
            m = metrics_tuple(r)
            cells.append([fmt(v) for v in m] if m else [r.status.split(":")[0], "", ""])
        me_, mp_ = (
            metrics_tuple(res[("t2paper", name, o, "noise+mismatch")]) for o in ("ESO", "PHSO")
        )
        imp = (
            [pct(improvement(me_[1], mp_[1])), pct(improvement(me_[2], mp_[2]))]
            if me_ and mp_
            else ["n/a", "n/a"]
        )
        md.append(
            f"| {name} | paper constants, noise + full (+) | "
            + " | ".join(cells[0] + cells[1] + imp)
            + " | | | | | |"
        )
    worst_sine_me = max(
        max(t2b[("sine", c)][0][1], t2b[("sine", c)][1][1])
        for c in conditions
        if t2b[("sine", c)][0] and t2b[("sine", c)][1]
    )
    sine_full = t2b[("sine", "noise + full mismatch (+)")]
    t2b_phdo_full = metrics_tuple(tuned[("sine", "noise + full mismatch (+)", "PHDO")])[1]
    md += [
        "",
        f"**Sub-micrometre tracking.** With the digital tuning the Table 2 sine is tracked "
        f"with ME at most {fmt(worst_sine_me)} um over all conditions and both observers "
        f"(noise {NOISE_STD:g} um, hysteresis +-10 %, a1 and a3 +-2 %, one-sample delay).",
        "",
        "**How the PHSO's advantage changes.** Without mismatch (nominal, noise only, "
        "hysteresis +-10 %) the PHSO beats the ESO, as in the paper. With a 2 % error in the "
        "linear part the order reverses: sine ME "
        f"ESO {fmt(sine_full[0][1])} vs PHSO {fmt(sine_full[1][1])} um. The reason is "
        "structural. A static-gain error needs an offset in the lumped disturbance of the "
        "order of 2 % of the stroke (several um), which both observers can only put into "
        "x3hat. The ESO's x3hat is a pure integrator and holds it. The PHSO's x3hat obeys "
        "the hysteresis model, which pulls it back into |x3| <= alpha/(beta + gamma) = "
        f"{exp.bounded_class().h_max:.3g} um at every input reversal. Outside that range "
        "the model's slope dh/du = alpha + (beta - gamma)|x3| exceeds a3/a1, so the loop "
        "gain through the hysteresis copy exceeds one at reversals and the input chatters "
        "(see the input panel of the figures). The integral action of the tuning keeps ME "
        "sub-micrometre for the PHSO too, but its MAXE then shows the reversal spikes. The "
        "paper's experiment found the PHSO better by about 40 %. That is consistent with a "
        "well-identified linear part (a3/a1 within a fraction of a percent) and with the "
        "hysteresis shape as the main model error. The remedy belongs in the observer: "
        "give the PHSO a separate integrating disturbance state, x2' = ... - a1 (x3 + d), "
        "d' = l4 (y - x1hat), so that x3hat stays a hysteresis state. That is the PHDO "
        "column (`bwdesign.DisturbanceHysteresisObserver`, the tuning's gains as "
        "(l1, l2, 0, l3): the same observable poles, the whole lumped correction into d): "
        f"sine ME under the full mismatch (+) {fmt(t2b_phdo_full)} um.",
        "",
        "With the paper's constants the ESO loop's errors are tens of um, and noise and "
        "mismatch change them little (the ZOH-induced error dominates); the PHSO loop "
        "diverges under the full mismatch: the same hysteresis-path gain above one, now "
        "with a loop too slow (lambda = 1, 2) to hold it.",
        "",
    ]
    for name, fname, fig_no in (
        ("sine", "fig7_table2_sine.png", 7),
        ("triangle", "fig8_table2_triangle.png", 8),
    ):
        for cond, suffix in (("noise + hysteresis +-10 %", ""), ("noise + full mismatch (+)",
                                                                   "_full_mismatch")):  # fmt: skip
            f = fname.replace(".png", f"{suffix}.png")
            fig, _ = plot_tracking_comparison(
                {"ESO": tuned[(name, cond, "ESO")], "PHSO": tuned[(name, cond, "PHSO")]},
                title=f"Table 2 {name}, digital tuning, {cond} (like the paper's Figure {fig_no})",
            )
            save(fig, out / f)
            md.append(f"![Figure {fig_no} analogue, {cond}]({f})")
    fig, _ = plot_tracking_comparison(
        {
            "ESO": res[("t2paper", "sine", "ESO", "nominal")],
            "PHSO": res[("t2paper", "sine", "PHSO", "nominal")],
        },
        title="Table 2 sine with the paper's constants (eq. 12 as printed, 0.2 ms), nominal",
    )
    save(fig, out / "fig7_table2_sine_paper_constants.png")
    md += ["![paper constants](fig7_table2_sine_paper_constants.png)", ""]
    doc["table2"] = {
        "settings": {
            "dt": DT,
            "paper_constants": SEC5,
            "digital_tuning": tk,
            "noise_std_um": NOISE_STD,
            "mismatch": {"hysteresis": hyst_only, "full_plus": full_plus, "full_minus": full_minus},
            "durations_s": {"paper_constants": dur_paper, "digital_tuning": 3.0},
        },
        "paper": PAPER_T2,
        "paper_constants": {
            f"{n}/{o}/{c}": res[("t2paper", n, o, c)].to_dict()
            for n in refs2
            for o in ("ESO", "PHSO")
            for c in ("nominal", "noise+mismatch")
        },
        "digital_tuning": {f"{n}/{c}/{o}": tuned[(n, c, o)].to_dict() for (n, c, o) in tuned},
        "beyond_factor_2": {"paper_constants": off2p, "digital_tuning": off2t},
    }

    # ---------------------------------------------------------------- peaking
    md += peaking_section(peak, out, plot_peaking, doc)

    md += [
        "",
        f"Total run time {time.perf_counter() - T0:.0f} s.",
        "",
    ]
    (out / "paper_tables.md").write_text("\n".join(md))
    log(f"wrote {args.out}/paper_tables.md")
    from bwdesign.output.jsonenc import json_safe

    (out / "paper_tables.json").write_text(json.dumps(json_safe(doc), indent=1))
    log(f"wrote {args.out}/paper_tables.json")
    return 0


# -- poles against simulated decay -------------------------------------------------------


def decay_check(exp, tuning) -> list[dict[str, Any]]:
    """Slowest pole of the analysis against the decay of the simulated tracking error."""
    hold = Step(amplitude=0.0, offset=10.0)
    rows = []
    cases = [
        ("paper constants, eq. 12 as printed", dict(**SEC5), {}, (8.0, 20.0)),
        (
            "paper constants, eq. 12 as printed, hysteresis_jump=True",
            dict(**SEC5, hysteresis_jump=True),
            {},
            (8.0, 20.0),
        ),
        (
            "digital tuning (no delay)",
            dict(tuning.controller_kwargs()),
            dict(integral_rate=tuning.integral_rate),
            (0.1, 0.2),
        ),
        (
            "digital tuning (no delay), hysteresis_jump=True",
            dict(tuning.controller_kwargs(), hysteresis_jump=True),
            dict(integral_rate=tuning.integral_rate),
            (0.1, 0.2),
        ),
    ]
    for label, kw, _, win in cases:
        loop = make_loop(exp, "phso", dt=DT, start=Start(xhat0=(2.0, 0, 0)), **kw)
        a = analyze_loop(loop)
        r = simulate(loop, hold, duration=win[1] + 0.01)
        sel = (r.t >= win[0]) & (r.t <= win[1])
        rate = -np.polyfit(r.t[sel], np.log(np.abs(r.e[sel])), 1)[0]
        rows.append(
            {
                "label": label,
                "predicted": a.slowest_decay_rate,
                "simulated": float(rate),
                "window": list(win),
            }
        )
    return rows


# -- peaking ---------------------------------------------------------------------------


def peaking_runs(exp, sim) -> dict[str, Any]:
    """Step references: before and after the remedy."""
    dt = DT
    # a user who pushes the digital loop: observer and law five times faster than the tuning
    g_fast = tuple(observer_gains(exp, [-1.0 / dt] * 3))
    lam = 1000.0
    base = dict(
        dt=dt,
        gains=g_fast,
        lambda1=lam,
        lambda2=lam,
        form="discrete",
        integral_rate=lam / 2,
        delay=True,
        start=Start(x0=(20.0, 0.0, 0.0), xhat0=(20.0, 0.0, 0.0), u_prev=20.0 * exp.a1 / exp.a3),
    )
    sharp = Step(amplitude=100.0, offset=20.0, t_step=0.05)
    smooth = Step(amplitude=100.0, offset=20.0, t_step=0.05, rise_time=0.01)
    out: dict[str, Any] = {"before": {}, "after": {}, "settings": {}}
    for obs in ("ESO", "PHSO"):
        out["before"][obs] = simulate(make_loop(exp, obs.lower(), **base), sharp, duration=0.3)
        limited = make_loop(exp, obs.lower(), u_limits=U_LIMITS_EXP, **base)
        out["after"][obs] = simulate(limited, smooth, duration=0.3)
    out["settings"] = {
        "gains": g_fast,
        "lambda": lam,
        "integral_rate": lam / 2,
        "step_um": 100.0,
        "from_um": 20.0,
        "rise_time_s": 0.01,
        "u_limits_V": U_LIMITS_EXP,
    }
    # the paper's high-gain continuous setting, sharp step (observer peaking)
    ref = Step(amplitude=30.0, offset=0.0, t_step=0.01)
    out["continuous"] = {
        obs: simulate_continuous(
            make_loop(sim, obs.lower(), **SEC42),
            ref,
            duration=0.08,
            solver=ContinuousSolver(output_dt=1e-5),
        )
        for obs in ("ESO", "PHSO")
    }
    return out


def _peak_stats(r: SimulationResult, t_step: float, target: float) -> dict[str, float]:
    """Input range, overshoot, estimate peaks within 30 ms of the step, final error."""
    after = r.t >= t_step
    near = after & (r.t <= t_step + 0.03)
    d = r.xhat - r.x
    tail = r.t >= r.t[0] + 0.9 * (r.t[-1] - r.t[0])
    return {
        "u_min": float(r.u.min()),
        "u_max": float(r.u.max()),
        "overshoot_um": float(np.max(r.x[after, 0]) - target) if np.any(after) else math.nan,
        "peak_x2_error": float(np.max(np.abs(d[near, 1]))) if np.any(near) else math.nan,
        "peak_x3_error": float(np.max(np.abs(d[near, 2]))) if np.any(near) else math.nan,
        "final_abs_error_um": float(np.max(np.abs(r.e[tail]))),
        "stable": r.stable,
    }


def peaking_section(peak, out: Path, plot_peaking, doc) -> list[str]:
    s = peak["settings"]
    md = [
        "## Peaking on a step reference, and the remedy",
        "",
        "The paper reports that a step reference makes both observers peak and destabilises "
        "the loop. In an exact-model loop the estimates do not peak by themselves (the "
        "observer sees the same input as the plant), but the step reaches the input directly: "
        "the law multiplies the jump of e by k1 (about lambda1 lambda2/a3), the held input "
        "jumps, the hysteresis jumps with it (which the ESO does not model, so its x2 and x3 "
        "estimates peak), and a high-gain loop asks for far more voltage than an amplifier "
        "has.",
        "",
        f"Setting: `paper_experiment`, dt = 0.2 ms, a loop pushed five times faster than the "
        f"digital tuning (observer triple pole at 5000 rad/s, lambda = {s['lambda']:g}, "
        f"integral {s['integral_rate']:g} 1/s, one-sample delay; no sensor noise, so that "
        "the estimate peaks are the step's), "
        f"a {s['step_um']:g} um step from {s['from_um']:g} um at t = 0.05 s. "
        f"Remedy: the smoothed reference `Step(rise_time={s['rise_time_s']:g})` (quintic, "
        f"continuous x_d' and x_d'') and the amplifier limits u in "
        f"[{s['u_limits_V'][0]:g}, {s['u_limits_V'][1]:g}] V (an assumed amplifier range) "
        "(`TrackingController(u_limits=...)`, the observer driven with the clipped input); "
        "`estimate_limits=` (clip the estimates outside the operating range before the law) "
        "is available for loops whose estimates leave the range.",
        "",
        "| run | observer | u range (V) | overshoot (um) | peak x2 estimation error within "
        "30 ms of the step (um/s) | peak x3 estimation error (um) | abs(e) over the last 10 % "
        "of the run (um) |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    stats: dict[str, Any] = {}
    target = s["from_um"] + s["step_um"]
    for phase, label in (("before", "sharp step, no limits"), ("after", "remedy")):
        for obs, r in peak[phase].items():
            st = _peak_stats(r, 0.05, target)
            stats[f"{phase}/{obs}"] = st
            md.append(
                f"| {label} | {obs} | {st['u_min']:.3g} .. {st['u_max']:.4g} | "
                f"{fmt(st['overshoot_um'], 3)} | {fmt(st['peak_x2_error'], 3)} | "
                f"{fmt(st['peak_x3_error'], 3)} | {fmt(st['final_abs_error_um'], 3)} |"
            )
    for obs, r in peak["continuous"].items():
        st = _peak_stats(r, 0.01, 30.0)
        stats[f"continuous/{obs}"] = st
        md.append(
            f"| Section 4.2 continuous loop, 30 um sharp step | {obs} | "
            f"{st['u_min']:.3g} .. {st['u_max']:.4g} | {fmt(st['overshoot_um'], 3)} | "
            f"{fmt(st['peak_x2_error'], 3)} | {fmt(st['peak_x3_error'], 3)} | "
            f"{fmt(st['final_abs_error_um'], 3)} |"
        )
    b, a = stats["before/ESO"], stats["after/ESO"]
    md += [
        "",
        f"Without the remedy the loop asks for up to {b['u_max']:.0f} V from an amplifier "
        f"with a {U_LIMITS_EXP[1]:g} V ceiling and overshoots by {b['overshoot_um']:.3g} um; "
        f"the ESO's velocity estimate is off by {b['peak_x2_error']:.3g} um/s at the step. "
        f"With the smoothed step and the limits the input stays within "
        f"[{a['u_min']:.3g}, {a['u_max']:.4g}] V and the overshoot is "
        f"{fmt(a['overshoot_um'], 3)} um. None of our exact-model loops became unstable on a "
        "step: the instability the paper reports needs something our simulation does not "
        "have (an amplifier that misbehaves when driven into its rails, a numerically "
        "differentiated u' meeting a step, or a forward-Euler hysteresis update, which is "
        "unstable for large |du| beta). In the continuous Section 4.2 loop the ESO's x2 "
        "estimate peaks by "
        f"{stats['continuous/ESO']['peak_x2_error']:.3g} um/s on a 30 um step while the "
        "PHSO, with the model's hysteresis jump, does not peak at all.",
        "",
        "![peaking before and after](fig_peaking.png)",
        "",
    ]
    fig, _ = plot_peaking(
        peak["before"],
        peak["after"],
        title="Step reference on paper_experiment, high-gain digital loop",
        t_range=(0.03, 0.15),
        labels=(
            "sharp step, no input limits",
            f"Step(rise_time=0.01) + u_limits {U_LIMITS_EXP} V",
        ),
    )
    save(fig, out / "fig_peaking.png")
    doc["peaking"] = {"settings": s, "stats": stats}
    return md


if __name__ == "__main__":
    sys.exit(main())
