"""Code generation: the certified discrete observers and controller as dependency-free C99.

The C templates live here (``templates/``) and nowhere else.
"""

from .export import OBSERVERS, CExport, c_sources, export_c
from .literals import PRECISIONS, c_literal

__all__ = ["OBSERVERS", "CExport", "c_sources", "export_c", "PRECISIONS", "c_literal"]
