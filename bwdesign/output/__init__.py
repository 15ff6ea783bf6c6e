"""Output layer: strict JSON encoding (and, below every writer, file output)."""

__all__ = []
