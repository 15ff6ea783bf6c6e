"""``bwdesign excite``: an input to play on the bench for identification.

With ``--simulate-noise`` the guessed plant's response (plus noise) is added
as a ``y`` column: simulated data, said so in the file's header.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .._version import __version__
from ..identify.excite import KINDS, RANGE_MARGIN, design_excitation, simulate_record
from ..model.config import load_plant
from ..output.files import prepare_file
from ..output.jsonenc import dump_json
from .args import EXIT_OK, UsageError, finite_float, nonneg_float, positive_float

__all__ = ["excite_args", "run_excite"]


def excite_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``bwdesign excite``."""
    p.add_argument("--plant", required=True, metavar="NAME_OR_TOML", help="rough stage guess")
    p.add_argument("--kind", choices=KINDS, default="multisine")
    p.add_argument("--umin", required=True, type=finite_float, metavar="V", help="amplifier min")
    p.add_argument("--umax", required=True, type=finite_float, metavar="V", help="amplifier max")
    p.add_argument(
        "--udot-max",
        required=True,
        type=positive_float,
        metavar="V/s",
        help="rate limit; at least the rate that crosses the range once in --duration (an "
        "error states it)",
    )
    p.add_argument("--duration", required=True, type=positive_float, metavar="S")
    p.add_argument("--dt", required=True, type=positive_float, metavar="S", help="sample time")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--simulate-noise",
        type=nonneg_float,
        metavar="UM",
        help="add a simulated y column: the plant's response plus this noise (µm)",
    )
    p.add_argument(
        "--offset",
        type=finite_float,
        default=0.0,
        metavar="UM",
        help="sensor offset of the simulated y (µm)",
    )
    p.add_argument("--out", required=True, metavar="FILE.csv", help="CSV to write (t,u[,y])")
    p.add_argument("--json", action="store_true", help="print one JSON summary on stdout")


def run_excite(args: argparse.Namespace) -> int:
    """Run ``bwdesign excite``."""
    out = Path(args.out)
    if out.suffix.lower() != ".csv":
        raise UsageError(f"--out must be a .csv file, got {args.out!r}")
    target = prepare_file(out, command="excite", what="--out")
    plant = load_plant(args.plant)
    t, u = design_excitation(
        plant,
        kind=args.kind,
        umin=args.umin,
        umax=args.umax,
        udot_max=args.udot_max,
        duration=args.duration,
        dt=args.dt,
        seed=args.seed,
    )
    cmd = (
        f"bwdesign excite --plant {args.plant} --kind {args.kind} --umin {args.umin:g} "
        f"--umax {args.umax:g} --udot-max {args.udot_max:g} --duration {args.duration:g} "
        f"--dt {args.dt:g} --seed {args.seed}"
    )
    head = [
        f"# bwdesign {__version__} excite: {args.kind} input for identification,",
        f"# within [{args.umin:g}, {args.umax:g}] V (spanning it to within "
        f"{100 * RANGE_MARGIN:g} % of each end) and |du/dt| <= {args.udot_max:g} V/s.",
        "# Units: t s, u V (held over each sample), y um (at the end of each sample).",
    ]
    cols = [t, u]
    names = "t,u"
    if args.simulate_noise is not None:
        rec = simulate_record(
            plant, u, args.dt, noise=args.simulate_noise, offset=args.offset, seed=args.seed + 1
        )
        cols.append(np.asarray(rec.y))
        names = "t,u,y"
        cmd += f" --simulate-noise {args.simulate_noise:g} --offset {args.offset:g}"
        head.append(
            f"# SIMULATED, NOT MEASURED: y is the exact ZOH response of plant {plant.name!r} "
            f"plus {args.simulate_noise:g} um Gaussian sensor noise (seed {args.seed + 1}) and "
            f"a {args.offset:g} um offset."
        )
    head.append(f"# Regenerate: {cmd} --out {out.name}")
    rows = "\n".join(",".join(f"{v:.12g}" for v in row) for row in zip(*cols, strict=True))
    target.write_text("\n".join(head) + "\n" + names + "\n" + rows + "\n")
    summary = {
        "out": str(out),
        "kind": args.kind,
        "samples": int(t.size),
        "u_min": float(u.min()),
        "u_max": float(u.max()),
        "udot_max_used": float(np.max(np.abs(np.diff(u))) / args.dt),
        "simulated": args.simulate_noise is not None,
    }
    if args.json:
        print(dump_json(summary))
    else:
        print(
            f"{out}: {t.size} samples, u in [{summary['u_min']:.4g}, {summary['u_max']:.4g}] V, "
            f"max |du/dt| {summary['udot_max_used']:.4g} V/s"
        )
    return EXIT_OK
