"""Every public name has documentation for the API reference (docs/api_names.py).

The API reference (``make docs``) is generated from the docstrings of the names in
``bwdesign.__all__`` and each subpackage's ``__all__``; a name without a docstring (or,
for a constant, a ``#:`` comment) would be an empty entry there.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("sphinx", reason="the docs extra (pip install -e '.[docs]')")


def _api_names():
    spec = importlib.util.spec_from_file_location("bwdesign_api_names", ROOT / "docs/api_names.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_every_public_name_is_documented():
    total, missing = _api_names().counts()
    assert total >= 200, total  # bwdesign.__all__ alone has 95 names
    assert not missing, f"public names without documentation: {missing}"


def test_the_api_pages_name_every_public_name(tmp_path):
    api = _api_names()
    import bwdesign

    pages = api.write_api_pages(tmp_path)
    text = "\n".join((tmp_path / f"{p}.rst").read_text() for p in pages)
    listed = {line.strip() for line in text.splitlines() if line.startswith("   ")}
    assert set(bwdesign.__all__) <= listed
    assert "bwdesign" in pages and "bwdesign-testing" in pages


def test_an_undocumented_name_is_counted(monkeypatch):
    api = _api_names()
    import bwdesign.testing as testing

    def bare():
        pass

    monkeypatch.setattr(testing, "failure_table", bare)
    _, missing = api.counts()
    assert "bwdesign.testing.failure_table" in missing
