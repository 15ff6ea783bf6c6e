"""The study cache: a stage's study read back instead of computed, when nothing it depends on
changed.

A study is a pure function of the stage file, the settings asked, the package's code and
the libraries' versions, so the command line keeps the parts it computed in the result
cache (:class:`bwdesign.output.ResultCache`, outside every output directory) and reads
them back the next time the same study is asked: ``bwdesign report`` and ``bwdesign
check`` (``--no-cache`` turns it off; the Python API uses it only when given a
:class:`StudyCache`).

The key (:meth:`StudyCache.key`) is the SHA-256 of

- the format of an entry (:data:`FORMAT`);
- the package: its version and a fingerprint of every file of its source folder
  (:func:`source_fingerprint`), so an editable install whose code changed never reads a
  study the old code computed;
- Python's and the libraries' versions (:func:`bwdesign.study.versions`), the machine
  and the platform: the solvers' answers may change with any of them;
- the stage: the SHA-256 of the file's bytes and the parsed configuration (every
  section as read, and the path as given, which the tracking runs' commands quote);
- ``allow_unbounded`` and the :class:`~bwdesign.study.StudySettings`.

A configuration without a file hash (built in Python) or whose representation is not
reproducible is never cached. One entry per key holds every part computed for it so
far; a later study that asks more parts computes only the missing ones and keeps the
union. Entries are pickles, read only from the user's own cache folder (the store
refuses entries other users could write). python-control's state-space objects are
not picklable and are not kept: in a study read from the cache,
``LoopAnalysis.systems``'s ``plant``, ``controller`` and ``loop`` and
``ErrorDynamics.systems`` are ``None``; no number the report, ``certificate.json`` or
the checks show comes from them. An entry that cannot be read back is a miss: the
study is computed again, never an error.
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import pickle
import platform
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .._version import __version__
from ..output.files import ResultCache
from .result import PARTS

__all__ = ["StudyCache", "source_fingerprint", "FORMAT"]

#: Version of the entry format (part of every key).
FORMAT = "bwdesign study cache 1"

_PARTS_KIND = "study"


@functools.cache
def source_fingerprint() -> str:
    """SHA-256 over every file of the installed package's folder (path and bytes).

    Compiled files (``__pycache__``) are left out: they follow the sources.
    """
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if "__pycache__" in p.parts or p.suffix in (".pyc", ".pyo") or not p.is_file():
            continue
        h.update(p.relative_to(root).as_posix().encode() + b"\0")
        h.update(p.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


class _Pickler(pickle.Pickler):
    """Pickles a study's parts; python-control objects (not picklable) become ``None``."""

    def reducer_override(self, obj: Any) -> Any:
        if type(obj).__module__.split(".", 1)[0] == "control":
            return (type(None), ())
        return NotImplemented


class StudyCache:
    """Where studies are kept between runs (see the module doc).

    Parameters
    ----------
    store : ResultCache, optional
        The cache folder (default: :func:`bwdesign.output.default_cache_dir`).
    """

    def __init__(self, store: ResultCache | None = None) -> None:
        self.store = ResultCache() if store is None else store

    def __repr__(self) -> str:
        return f"StudyCache({self.store!r})"

    def key(
        self,
        config: Any,
        allow_unbounded: bool,
        settings: Any,
        versions: Mapping[str, str],
    ) -> str | None:
        """The key of a study, or ``None`` when this configuration is not cached."""
        stage = repr(config)
        if not getattr(config, "sha256", "") or " at 0x" in stage or " at 0x" in repr(settings):
            return None
        material = {
            "format": FORMAT,
            "bwdesign": __version__,
            "source": source_fingerprint(),
            "versions": dict(versions),
            "python": sys.version,
            "platform": [sys.platform, platform.machine()],
            "file_sha256": config.sha256,
            "config": stage,
            "allow_unbounded": bool(allow_unbounded),
            "settings": repr(settings),
        }
        blob = json.dumps(material, sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()

    def load(self, key: str) -> dict[str, Any] | None:
        """The parts kept under ``key`` (``None``: a miss, also for an unreadable entry)."""
        parts = self.read_object(key, _PARTS_KIND)
        if not isinstance(parts, dict) or not set(parts) <= set(PARTS):
            return None
        return parts

    def save(self, key: str, parts: Mapping[str, Any]) -> bool:
        """Keep ``parts`` under ``key``; ``False`` when they were not kept."""
        buf = io.BytesIO()
        try:
            _Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL).dump(dict(parts))
        except Exception:  # noqa: BLE001 - a part that does not pickle is not kept
            return False
        return self.store.write(key, _PARTS_KIND, buf.getvalue())

    def read_object(self, key: str, kind: str) -> Any:
        """The object pickled under ``key`` and ``kind`` (``None``: a miss, also for an
        entry that does not load)."""
        payload = self.store.read(key, kind)
        if payload is None:
            return None
        try:
            return pickle.loads(payload)
        except Exception:  # noqa: BLE001 - an entry that does not load is a miss
            return None

    def write_extra(self, key: str, kind: str, payload: bytes) -> bool:
        """Keep bytes derived from the study ``key`` under ``kind``."""
        return self.store.write(key, kind, payload)
