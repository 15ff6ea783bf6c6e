"""``bwdesign sweep`` (registered in :mod:`bwdesign.cli.main`).

Exit codes: 0 written (whatever the scenarios did: instability is a result);
1 the sweep could not be completed (a chunk failed after its retries, no scheduler);
2 bad input with one ``error:`` line, nothing written.
"""

from __future__ import annotations

import argparse
import math
import sys

from ..design.tuning import stage_tuning
from ..extras import require
from ..model.config import load_config
from ..model.uncertainty import UncertaintyBox
from ..output.files import prepare_directory
from ..output.jsonenc import dump_json
from ..sim.sweep import (
    WORKERS_PER_CPU,
    SweepError,
    SweepSpec,
    check_observers,
    check_samples,
    check_scheduler,
    check_workers,
    draw_scenarios,
    run_sweep,
    spec_from_config,
)
from .args import EXIT_NO, EXIT_OK, nonneg_float, nonneg_int, positive_float, positive_int

__all__ = [
    "sweep_args",
    "run_sweep_command",
    "parse_observers",
    "check_limits",
]


def parse_observers(text: str) -> tuple[str, ...]:
    """``"phso, ESO"`` -> ``("phso", "eso")``: known names, each once."""
    return check_observers(tuple(o.strip().lower() for o in text.split(",") if o.strip()))


def check_limits(args: argparse.Namespace) -> tuple[tuple[str, ...], UncertaintyBox | None]:
    """Every limit the arguments alone decide, before any file is read or any work done.

    Returns the observers and the ``--uncertainty`` box (None without it).
    """
    observers = parse_observers(args.observers)
    check_samples(args.samples, len(observers))
    if args.scheduler is None:
        check_workers(args.workers)
    check_scheduler(args.scheduler)
    if args.uncertainty is None:
        return observers, None
    return observers, UncertaintyBox.parse(args.uncertainty, name="--uncertainty")


def sweep_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign sweep``."""
    p.add_argument("--config", required=True, metavar="STAGE.toml", help="stage configuration")
    p.add_argument(
        "--samples",
        required=True,
        type=positive_int,
        metavar="N",
        help="scenarios (> 0; at most what fits in half the memory, see the error message)",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--uncertainty",
        metavar="SPEC",
        help="box half-widths, e.g. a1=2%%,a3=2%%,alpha=10%% (relative) or alpha=0.01 (absolute);"
        " default: the config's [uncertainty] section",
    )
    p.add_argument("--distribution", choices=("uniform", "normal"), default="uniform")
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the draw (>= 0)")
    p.add_argument(
        "--observers",
        default="phso,eso",
        help="observers to run: phso, eso, phdo, or the baselines pi, pid, pi-bwff, pi-piff "
        "(no observer; tuned by the phase-margin rule) (default phso,eso)",
    )
    p.add_argument(
        "--tuning",
        choices=("config", "digital"),
        default="config",
        help="config: [observer] gains and [controller] lambdas; digital: the digital tuning",
    )
    p.add_argument(
        "--form",
        choices=("continuous", "discrete"),
        default="continuous",
        help="form of eq. (12) with --tuning config",
    )
    p.add_argument(
        "--duration",
        type=positive_float,
        default=None,
        metavar="S",
        help="seconds per scenario (default three reference periods, at least 1 s)",
    )
    p.add_argument(
        "--noise-std",
        type=nonneg_float,
        default=0.0,
        metavar="STD",
        help="sensor noise std (length unit)",
    )
    p.add_argument("--delay", action="store_true", help="one-sample computation delay")
    p.add_argument(
        "--start",
        choices=("reference", "rest"),
        default="reference",
        help="start every scenario on the reference (as the report's runs; default) or at rest",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=nonneg_int,
        default=None,
        metavar="K",
        help="local Dask worker processes (default: one per CPU, at most "
        f"{WORKERS_PER_CPU} per CPU; 0: in this process)",
    )
    where.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="address of a running dask.distributed scheduler, tcp://HOST:PORT",
    )
    p.add_argument(
        "--chunk-size",
        type=positive_int,
        default=1000,
        metavar="M",
        help="scenarios per task (default 1000)",
    )
    p.add_argument(
        "--timeout",
        type=positive_float,
        default=10.0,
        metavar="S",
        help="seconds to wait for --scheduler",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="write into a directory holding other files (they are kept, never overwritten)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar on stderr")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")


def _spec(config, args, observers, box) -> SweepSpec:
    return spec_from_config(
        config,
        law=stage_tuning(config, args.tuning),
        form=args.form,
        observers=observers,
        noise_std=args.noise_std,
        duration=args.duration,
        delay=args.delay,
        start=args.start,
        uncertainty=box,
    )


def _progress(quiet: bool):
    if quiet:
        return None, None
    tqdm = require(
        "tqdm", extra="sweep", feature="the sweep's progress bar (--quiet needs none)"
    ).tqdm
    bar = tqdm(total=0, unit="chunk", file=sys.stderr, desc="sweep", leave=False)

    def update(done: int, total: int) -> None:
        bar.total = total
        bar.n = done
        bar.refresh()

    return update, bar


def _envelope_text(spec: SweepSpec, s: dict) -> str:
    """``; 12 outside the envelope |u'| <= 397 V/s (up to 8.7x); worst replay differs ...``."""
    iu = spec.params.input_unit
    text = ""
    if s["outside_envelope"] is not None:
        text = f"; {s['outside_envelope']} outside the envelope |u'| <= {spec.udot_max:.4g} {iu}/s"
        if s["outside_envelope"]:
            text += f" (up to {s['worst_envelope_ratio']:.3g}x)"
    rep = s.get("replay")
    if rep and rep["sensitive"]:
        d = rep["replay_difference"]
        diff = "diverges differently" if math.isinf(d) else f"differs by {100 * d:.2g} %"
        text += (
            f"; worst row sensitive to rounding (its replay {diff}): "
            "rows like it reproduce only statistically"
        )
    return text


def run_sweep_command(args: argparse.Namespace) -> int:
    from ..report.sweep import write_sweep

    observers, box = check_limits(args)
    target = prepare_directory(args.out, command="sweep", force=args.force, what="--out")
    config = load_config(args.config)
    spec = _spec(config, args, observers, box)
    scenarios = draw_scenarios(
        spec.params, spec.box, args.samples, seed=args.seed, distribution=args.distribution
    )
    progress, bar = _progress(args.quiet)
    try:
        table = run_sweep(
            spec,
            scenarios,
            chunk_size=args.chunk_size,
            workers=args.workers,
            scheduler=args.scheduler,
            timeout=args.timeout,
            progress=progress,
        )
    except SweepError as err:
        print(f"sweep failed: {err}", file=sys.stderr)
        return EXIT_NO
    finally:
        if bar is not None:
            bar.close()
    settings = {"seed": args.seed, "distribution": args.distribution, "samples": args.samples}
    summary = write_sweep(target, spec, table, settings)
    if args.json:
        print(
            dump_json(
                {
                    "out_dir": str(args.out),
                    "summary": summary,
                    "bounds": spec.box.check(spec.params),
                    "columns": list(table),
                }
            )
        )
        return EXIT_OK
    for obs, s in summary.items():
        me = s["me"]
        med = (
            "-"
            if me is None
            else f"ME p50 {me['p50']:.4g}, p99 {me['p99']:.4g}, max {me['max']:.4g}"
        )
        print(
            f"{obs.upper()}: {s['scenarios']} scenarios, {s['unstable']} unstable; {med} "
            f"{spec.params.length_unit}{_envelope_text(spec, s)}"
        )
    print(f"{args.out}/scenarios.parquet, {args.out}/report.md")
    return EXIT_OK
