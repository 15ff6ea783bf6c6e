"""Command line: ``bwdesign SUBCOMMAND`` (also ``python -m bwdesign``). Nothing imports this
package.
"""

from .main import main

__all__ = ["main"]
