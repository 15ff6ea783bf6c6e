"""Command line: ``bwdesign SUBCOMMAND`` (also ``python -m bwdesign``).

Exit codes: 0 success; 1 a well-formed "no" (nothing certified, synthesis
infeasible); 2 bad input, reported as one ``error:`` line on stderr with no
traceback and nothing written; 130 interrupted (Ctrl-C): one ``error:
interrupted`` line, the previous output untouched.

Module-level imports stay light (no numpy): each command imports its work when
it runs, inside :func:`main`, so a Ctrl-C while it loads is handled too.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

from .. import interrupts
from ..errors import BWDesignError, NotCertifiedError
from .args import (
    EXIT_BAD_INPUT,
    EXIT_INTERRUPTED,
    EXIT_NO,
    Parser,
    add_plant_args,
)

#: Longest error line printed (characters).
MAX_ERROR_CHARS = 1000

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


COMMANDS: list[Command] = [
    (
        "params",
        "print a plant's parameters and bounded-class verdict",
        _params_args,
        _lazy("cli.params", "run_params"),
    ),
    (
        "certify",
        "check observer gains against an input-rate envelope (four certificate tiers)",
        _lazy("cli.certify", "certify_args"),
        _lazy("cli.certify", "run_certify"),
    ),
    (
        "synthesize",
        "find observer gains certified for an input-rate envelope (LMI synthesis)",
        _lazy("cli.certify", "synthesize_args"),
        _lazy("cli.certify", "run_synthesize"),
    ),
    (
        "simulate",
        "simulate the sampled tracking loop (observer + eq. 12) and report its error",
        _lazy("cli.simulate", "simulate_args"),
        _lazy("cli.simulate", "run_simulate"),
    ),
    (
        "export-c",
        "export the certified discrete observers and controller as dependency-free C99",
        _lazy("cli.export_c", "export_c_args"),
        _lazy("cli.export_c", "run_export_c"),
    ),
    (
        "sweep",
        "Monte Carlo sweep of the sampled tracking loop over an uncertainty box (Dask)",
        _lazy("cli.sweep", "sweep_args"),
        _lazy("cli.sweep", "run_sweep_command"),
    ),
    (
        "check",
        "check the [requirements] of stage files (exit 1 when one fails), for CI",
        _lazy("cli.check", "check_args"),
        _lazy("cli.check", "run_check"),
    ),
    (
        "report",
        "write the certified-gains report (Markdown, HTML, JSON, figures) for a stage config",
        _lazy("cli.report", "report_args"),
        _lazy("cli.report", "run_report"),
    ),
    (
        "init",
        "write a commented starter stage config (every section and key, units and defaults)",
        _lazy("cli.init", "init_args"),
        _lazy("cli.init", "run_init"),
    ),
    (
        "presets",
        "list the presets: bundled stage configs (--plant, --config, init --preset) and parameter "
        "sets (--plant)",
        _lazy("cli.init", "presets_args"),
        _lazy("cli.init", "run_presets"),
    ),
    (
        "identify",
        "fit the stage model to a measured (t, u, y) record; write a stage TOML with intervals",
        _lazy("cli.identify", "identify_args"),
        _lazy("cli.identify", "run_identify"),
    ),
    (
        "validate",
        "simulate a stage file (either form) on a record's input: fit percent and RMS error",
        _lazy("cli.validate", "validate_args"),
        _lazy("cli.validate", "run_validate"),
    ),
    (
        "excite",
        "design an identification input (within amplifier range and rate limit) as CSV",
        _lazy("cli.excite", "excite_args"),
        _lazy("cli.excite", "run_excite"),
    ),
]


def _command_word(argv: Sequence[str]) -> str | None:
    """The subcommand ``argv`` names: its first word that is not an option (the program's
    own options, ``--version`` and ``--help``, take no value)."""
    return next((a for a in argv if not a.startswith("-")), None)


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand; given the command line ``argv``, only the options of
    the subcommand it names are added (each command's options import its module, and a
    report read from the study cache should not wait for the identification's imports)."""
    from .._version import __version__  # importlib.metadata: not before main() runs

    word = None if argv is None else _command_word(argv)
    parser = Parser(prog="bwdesign", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"bwdesign {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="SUBCOMMAND", parser_class=Parser)
    sub.required = True
    for name, help_text, add_args, run in COMMANDS:
        p = sub.add_parser(name, help=help_text, description=help_text)
        if argv is None or name == word:
            add_args(p)
        p.set_defaults(_run=run)
    return parser


def main(argv: Sequence[str] | None = None, *, then_ignore_sigint: bool = False) -> int:
    """Entry point; returns the exit code.

    A Ctrl-C anywhere (also one a library swallowed: see :mod:`bwdesign.interrupts`)
    ends the command with one ``error: interrupted`` line and exit code 130;
    outputs are committed only when no interrupt is pending, so the previous
    output stays untouched. ``then_ignore_sigint``: the process exits after
    this (the console script), so SIGINT is ignored once the command ended.
    """
    try:
        with interrupts.handling(then_ignore=then_ignore_sigint):
            try:
                argv = sys.argv[1:] if argv is None else list(argv)
                args = build_parser(argv).parse_args(argv)
                code = args._run(args)
            except BaseException:
                interrupts.check()  # an interrupt that surfaced as another error
                raise
            interrupts.check()
            return code
    except KeyboardInterrupt:
        return interrupted()
    except NotCertifiedError as err:
        print("not certified: " + " ".join(str(err).split()), file=sys.stderr)
        return EXIT_NO
    except BWDesignError as err:
        text = " ".join(str(err).split())
        if len(text) > MAX_ERROR_CHARS:  # e.g. a huge list quoted from a config file
            text = text[: MAX_ERROR_CHARS - 3] + "..."
        print("error: " + text, file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:
        # the reader went away (e.g. `bwdesign ... --json | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_NO


def interrupted() -> int:
    """Report a Ctrl-C: one ``error: interrupted`` line; returns :data:`EXIT_INTERRUPTED`."""
    with contextlib.suppress(OSError, ValueError):  # stderr closed: the code still says it
        print("error: interrupted", file=sys.stderr, flush=True)
    return EXIT_INTERRUPTED
