"""Command line: ``bwdesign SUBCOMMAND`` (also ``python -m bwdesign``).

Exit codes: 0 success; 1 a well-formed "no" (nothing certified, synthesis
infeasible); 2 bad input, reported as one ``error:`` line on stderr with no
traceback and nothing written.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from . import __version__
from .config import load_plant
from .errors import BWDesignError
from .params import PRESET_NOTES, BoucWenParams

EXIT_OK, EXIT_NO, EXIT_BAD_INPUT = 0, 1, 2


class UsageError(BWDesignError, ValueError):
    """Bad command-line input."""


class _Parser(argparse.ArgumentParser):
    """argparse with the package's error convention: one ``error:`` line, exit 2."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{self.prog}: {message}")


def json_safe(obj: Any) -> Any:
    """Replace non-finite floats by ``None`` so the output is strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    return obj


def dump_json(doc: dict[str, Any]) -> str:
    return json.dumps(json_safe(doc), indent=2, allow_nan=False)


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def nonneg_float(text: str) -> float:
    """argparse type: a finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return value


def finite_float(text: str) -> float:
    """argparse type: a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def gains_triple(text: str) -> tuple[float, float, float]:
    """argparse type: ``l1,l2,l3``, three finite numbers."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(
            f"expected three comma-separated gains l1,l2,l3, got {text!r}"
        )
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"gains must be numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"gains must be finite, got {text!r}")
    return values  # type: ignore[return-value]


def add_plant_args(p: argparse.ArgumentParser) -> None:
    """``--plant`` and ``--allow-unbounded``, shared by every subcommand."""
    p.add_argument(
        "--plant",
        required=True,
        metavar="NAME_OR_TOML",
        help="preset name (paper_experiment, ...) or a stage .toml file",
    )
    p.add_argument(
        "--allow-unbounded",
        action="store_true",
        help="accept parameters outside the bounded Bouc-Wen class",
    )
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")


# -- params ------------------------------------------------------------------


def plant_summary(params: BoucWenParams) -> dict[str, Any]:
    """Parameters, derived linear quantities and the bounded-class verdict."""
    verdict = params.bounded_class()
    wn = math.sqrt(params.a1)
    doc: dict[str, Any] = {
        "plant": params.to_dict(),
        "derived": {
            "natural_frequency_hz": wn / (2 * math.pi),
            "damping_ratio": params.a2 / (2 * wn),
            "static_gain": params.static_gain,
            "static_gain_unit": f"{params.length_unit}/{params.input_unit}",
        },
        "bounded_class": verdict.to_dict(),
    }
    if params.name in PRESET_NOTES:
        doc["note"] = PRESET_NOTES[params.name]
    return doc


def _cmd_params(args: argparse.Namespace) -> int:
    params = load_plant(args.plant)
    doc = plant_summary(params)
    if args.json:
        print(dump_json(doc))
        return EXIT_OK
    lu, iu = params.length_unit, params.input_unit
    print(f"plant: {params.name or '(unnamed)'}")
    if "note" in doc:
        print(f"  {doc['note']}")
    units = {
        "a1": "1/s^2",
        "a2": "1/s",
        "a3": f"{lu}/({iu} s^2)",
        "alpha": f"{lu}/{iu}",
        "beta": f"1/{iu}",
        "gamma": f"1/{iu}",
    }
    for k, unit in units.items():
        print(f"  {k:<6} = {getattr(params, k):<14.8g} {unit}")
    if params.physical is not None:
        ph = params.physical
        print("physical quantities:")
        for k in ("m", "b", "k", "d", "alpha0"):
            print(f"  {k:<6} = {getattr(ph, k):.8g}")
    d = doc["derived"]
    print("linear part:")
    print(f"  natural frequency sqrt(a1)/(2 pi) = {d['natural_frequency_hz']:.6g} Hz")
    print(f"  damping ratio a2/(2 sqrt(a1))     = {d['damping_ratio']:.4g}")
    print(f"  static gain a3/a1                 = {d['static_gain']:.6g} {lu}/{iu}")
    v = doc["bounded_class"]
    print(f"bounded class: {'yes' if v['bounded'] else 'NO'}")
    print(f"  {v['reason']}")
    return EXIT_OK


# -- registry ----------------------------------------------------------------

Command = tuple[
    str, str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]
]


def _params_args(p: argparse.ArgumentParser) -> None:
    add_plant_args(p)


def _lazy(module: str, name: str) -> Callable[..., Any]:
    """A command hook imported on first use (keeps ``bwdesign --help`` light)."""

    def call(*args: Any) -> Any:
        from importlib import import_module

        return getattr(import_module(f"bwdesign.{module}"), name)(*args)

    return call


def _report_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", required=True, metavar="FILE.toml", help="stage configuration")
    p.add_argument("--out", required=True, metavar="DIR", help="report directory (replaced)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument(
        "--allow-unbounded",
        action="store_true",
        help="accept parameters outside the bounded Bouc-Wen class",
    )


def _cmd_report(args: argparse.Namespace) -> int:
    from .config import load_config
    from .report import write_report

    outcome = write_report(
        load_config(args.config), args.out, quiet=args.quiet, allow_unbounded=args.allow_unbounded
    )
    print(f"{outcome.out_dir}/report.md: {outcome.verdict}")
    return EXIT_OK if outcome.certified else EXIT_NO


COMMANDS: list[Command] = [
    ("params", "print a plant's parameters and bounded-class verdict", _params_args, _cmd_params),
    (
        "certify",
        "check observer gains against an input-rate envelope (four certificate tiers)",
        _lazy("_cli_certify", "certify_args"),
        _lazy("_cli_certify", "run_certify"),
    ),
    (
        "synthesize",
        "find observer gains certified for an input-rate envelope (LMI synthesis)",
        _lazy("_cli_certify", "synthesize_args"),
        _lazy("_cli_certify", "run_synthesize"),
    ),
    (
        "simulate",
        "simulate the sampled tracking loop (observer + eq. 12) and report its error",
        _lazy("_cli_simulate", "simulate_args"),
        _lazy("_cli_simulate", "run_simulate"),
    ),
    (
        "report",
        "write the certified-gains report (Markdown, HTML, JSON, figures) for a stage config",
        _report_args,
        _cmd_report,
    ),
]


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="bwdesign", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"bwdesign {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="SUBCOMMAND", parser_class=_Parser)
    sub.required = True
    for name, help_text, add_args, run in COMMANDS:
        p = sub.add_parser(name, help=help_text, description=help_text)
        add_args(p)
        p.set_defaults(_run=run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    try:
        args = build_parser().parse_args(argv)
        return args._run(args)
    except BWDesignError as err:
        print("error: " + " ".join(str(err).split()), file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:
        # the reader went away (e.g. `bwdesign ... --json | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_NO
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return EXIT_BAD_INPUT
