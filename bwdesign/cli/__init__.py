"""Command line: ``bwdesign SUBCOMMAND`` (also ``python -m bwdesign``). Nothing imports this
package.

:func:`main` is the program (the console script ``bwdesign`` and ``python -m
bwdesign``): :func:`bwdesign.cli.main.main`, after which SIGINT is ignored
while the process exits, so a late Ctrl-C prints no traceback. The imports
before it are light (the package ``bwdesign`` loads its API on first use).
"""

from __future__ import annotations

from collections.abc import Sequence

from . import main as _commands


def main(argv: Sequence[str] | None = None) -> int:
    """The ``bwdesign`` program; returns the exit code (130 after Ctrl-C)."""
    try:
        return _commands.main(argv, then_ignore_sigint=True)
    except KeyboardInterrupt:  # before the handler was installed
        return _commands.interrupted()


__all__ = ["main"]
