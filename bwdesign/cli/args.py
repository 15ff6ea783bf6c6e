"""Argument types and shared options of the command line."""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

from ..errors import UsageError

EXIT_OK, EXIT_NO, EXIT_BAD_INPUT = 0, 1, 2
#: Exit code after Ctrl-C (SIGINT): 128 + 2, as shells report a process SIGINT ended.
EXIT_INTERRUPTED = 130


#: A token that is a value, never an option: a negative number or a list of numbers
#: starting with one (``-8,64,-512``, ``-1e3``, ``-.5``).
_NEGATIVE_VALUE = re.compile(r"^-(\d|\.\d)")


def join_negative_values(argv: Sequence[str]) -> list[str]:
    """``--opt -8,64,-512`` -> ``--opt=-8,64,-512``, so negative values read as written.

    argparse only takes ``-8`` or ``-0.5`` as a value; ``-8,64,-512`` or
    ``-1e3`` would be read as an unknown option. No option of bwdesign starts
    with a digit, so such a token is always the value of the long option before it.
    """
    out: list[str] = []
    for tok in argv:
        prev = out[-1] if out else ""
        if (
            _NEGATIVE_VALUE.match(tok)
            and prev.startswith("--")
            and prev != "--"
            and "=" not in prev
        ):
            out[-1] = f"{prev}={tok}"
        else:
            out.append(tok)
    return out


class Parser(argparse.ArgumentParser):
    """argparse with the package's error convention: one ``error:`` line, exit 2."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{self.prog}: {message}")

    def parse_known_args(self, args: Sequence[str] | None = None, namespace: Any = None):
        argv = sys.argv[1:] if args is None else args
        return super().parse_known_args(join_negative_values(argv), namespace)


def integer(text: str) -> int:
    """argparse type: an integer (its range is checked where it is used)."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def positive_int(text: str) -> int:
    """argparse type: an integer > 0."""
    v = integer(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected an integer > 0, got {v}")
    return v


def nonneg_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    v = integer(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {v}")
    return v


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


def gains_list(text: str, counts: tuple[int, ...] = (3,)) -> tuple[float, ...]:
    """``l1,l2,...``: ``counts`` comma-separated finite numbers (the one gains parser)."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in counts:
        many = " or ".join({3: "three", 4: "four"}.get(n, str(n)) for n in counts)
        names = " or ".join(",".join(f"l{i + 1}" for i in range(n)) for n in counts)
        raise argparse.ArgumentTypeError(
            f"expected {many} comma-separated gains {names}, got {text!r}"
        )
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"gains must be numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"gains must be finite, got {text!r}")
    return values


def gains_triple(text: str) -> tuple[float, float, float]:
    """argparse type: ``l1,l2,l3``, three finite numbers."""
    return gains_list(text, (3,))  # type: ignore[return-value]


def observer_gains_arg(text: str) -> tuple[float, ...]:
    """argparse type: three (phso, eso) or four (phdo) comma-separated finite gains."""
    return gains_list(text, (3, 4))


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
