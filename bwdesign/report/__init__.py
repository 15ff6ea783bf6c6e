"""Reports: the document model (Markdown + HTML) and the certified-gains report.

The certified-gains report renders a computed study (:mod:`bwdesign.study`):
:func:`render` turns a :class:`~bwdesign.study.Study` into a :class:`Document`,
:func:`write_report` computes the study of a stage and writes the report.
"""

from .certified import ReportOutcome, render, write_report
from .document import Document

__all__ = ["Document", "ReportOutcome", "render", "write_report"]
