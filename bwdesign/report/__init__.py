"""Reports: the document model (Markdown + HTML) and the certified-gains report."""

from .certified import DEFAULT_DECAY, ReportOutcome, certificate_document, write_report
from .document import Document

__all__ = ["Document", "ReportOutcome", "certificate_document", "write_report", "DEFAULT_DECAY"]
