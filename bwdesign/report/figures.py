"""Writing a report's figures: drawn, or the bytes drawn before for the very same study.

A figure is a pure function of the study it shows, so a report whose study was read
from the study cache (:mod:`bwdesign.study.cache`) also reads the figures drawn for it
(kept under the study's key, kind ``figures``) instead of drawing them again: a
report written from the cache is byte for byte the one computed without it, and
matplotlib is not even imported. Figures are drawn (by :mod:`bwdesign.plotting`) only
when they were not kept.

A writer made with ``workers=2`` draws its figures at :meth:`FigureWriter.finish`, half of
them in a second process forked for it (:mod:`bwdesign.study.background`): the same
figures, drawn on two cores. A figure the second process did not deliver is drawn here.
"""

from __future__ import annotations

import pickle
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ..study import background

__all__ = ["FigureWriter", "as_writer", "kept_figures", "keep_figures"]

#: The cache entry kind of a study's figures.
FIGURES_KIND = "figures"


class FigureWriter:
    """Writes figures into one folder (a staging folder of the output layer).

    Parameters
    ----------
    folder : path
        Created when missing.
    kept : mapping of str to bytes, optional
        Figures already drawn for this study, by file name: written as they are.
    workers : int
        2 or more: figures are drawn at :meth:`finish`, every second one by a second
        process (where one can be forked); 1: each is drawn when saved.
    """

    def __init__(
        self, folder: str | Path, kept: Mapping[str, bytes] | None = None, *, workers: int = 1
    ) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.kept = dict(kept or {})
        self.written: dict[str, Path] = {}
        self.workers = workers
        self._pending: list[tuple[str, Callable[[], Any]]] = []

    @property
    def name(self) -> str:
        """The folder's name (documents refer to ``<name>/<figure>``)."""
        return self.folder.name

    def save(self, filename: str, draw: Callable[[], Any]) -> None:
        """Write ``filename``: the kept bytes, else the figure ``draw()`` returns."""
        path = self.folder / filename
        data = self.kept.get(filename)
        if isinstance(data, bytes):
            path.write_bytes(data)
        elif self.workers >= 2:
            self._pending.append((filename, draw))
        else:
            _draw(draw, path)
        self.written[filename] = path

    def finish(self) -> None:
        """Draw the figures saved but not drawn yet (``workers >= 2``): two processes at it."""
        pending, self._pending = self._pending, []
        if not pending:
            return
        from ..plotting import figures  # noqa: F401 - imported once, before the fork

        def task(filename: str, draw: Callable[[], Any]) -> Callable[[], str]:
            def run() -> str:
                _draw(draw, self.folder / filename)
                return filename

            return run

        theirs = pending[1::2]
        other = background.start([(f, task(f, d)) for f, d in theirs]) if len(pending) > 1 else None
        try:
            for filename, draw in pending if other is None else pending[0::2]:
                _draw(draw, self.folder / filename)
            for filename, draw in theirs if other is not None else ():
                if not other.result(filename)[0]:
                    _draw(draw, self.folder / filename)
        finally:
            if other is not None:
                other.close()

    def contents(self) -> dict[str, bytes]:
        """The bytes of every figure written, by file name."""
        return {name: path.read_bytes() for name, path in self.written.items()}


def _draw(draw: Callable[[], Any], path: Path) -> None:
    from ..plotting.figures import save_figure

    save_figure(draw(), path)


def as_writer(figs: FigureWriter | str | Path) -> FigureWriter:
    """A :class:`FigureWriter` for a folder given as a path (or the writer itself)."""
    return figs if isinstance(figs, FigureWriter) else FigureWriter(figs)


def kept_figures(cache: Any, key: str | None) -> dict[str, bytes] | None:
    """The figures kept for the study ``key`` in ``cache`` (a StudyCache), or ``None``."""
    if cache is None or key is None:
        return None
    kept = cache.read_object(key, FIGURES_KIND)
    if not isinstance(kept, dict) or not all(
        isinstance(k, str) and isinstance(v, bytes) for k, v in kept.items()
    ):
        return None
    return kept


def keep_figures(cache: Any, key: str | None, writer: FigureWriter) -> bool:
    """Keep the figures ``writer`` wrote for the study ``key`` (``False``: not kept)."""
    if cache is None or key is None:
        return False
    try:
        payload = pickle.dumps(writer.contents(), protocol=pickle.HIGHEST_PROTOCOL)
    except OSError:
        return False
    return cache.write_extra(key, FIGURES_KIND, payload)
