"""The public names the API reference documents, and which of them have no documentation.

The public API is ``bwdesign.__all__`` (re-exported name by name in
``bwdesign/__init__.py``) and the ``__all__`` of each subpackage. ``conf.py`` writes
one autosummary page per module from this list at build time, and
``tests/test_api_docs.py`` checks that every name has a docstring (or, for a
constant, a ``#:`` comment, which autodoc shows).

Run ``python docs/api_names.py`` for the counts.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
from dataclasses import is_dataclass
from pathlib import Path

#: Subpackages that are not a library API: the command line has one entry point.
NOT_API = {"bwdesign.cli", "bwdesign.__main__"}


def api_modules() -> list[str]:
    """``bwdesign`` and every subpackage with an ``__all__``, top-level first."""
    import bwdesign

    names = ["bwdesign"]
    for m in pkgutil.walk_packages(bwdesign.__path__, "bwdesign."):
        if m.ispkg and m.name not in NOT_API:
            if getattr(importlib.import_module(m.name), "__all__", None):
                names.append(m.name)
    return names


def public_names() -> dict[str, list[str]]:
    """For each API module, the names it documents.

    A class or function re-exported by several API modules is documented once, under
    the first of them (``bwdesign`` first, then the subpackages in order).
    """
    seen: set[int] = set()
    out: dict[str, list[str]] = {}
    for mod_name in api_modules():
        mod = importlib.import_module(mod_name)
        own = []
        for n in mod.__all__:
            obj = getattr(mod, n)
            if _is_object(obj):
                if id(obj) in seen:
                    continue
                seen.add(id(obj))
            own.append(n)
        out[mod_name] = sorted(own)
    return out


def _is_object(obj) -> bool:
    """A class, function or module: one identity wherever it is re-exported."""
    return inspect.isclass(obj) or inspect.isroutine(obj) or inspect.ismodule(obj)


def _attr_doc(module_name: str, name: str) -> str:
    """The ``#:`` comment (or string after it) of a module-level constant, as autodoc reads it."""
    from sphinx.pycode import ModuleAnalyzer

    try:
        docs = ModuleAnalyzer.for_module(module_name).find_attr_docs()
    except Exception:  # a module without source
        return ""
    return " ".join(docs.get(("", name), [])).strip()


def documentation(module_name: str, name: str) -> str:
    """The documentation a public name has ("" when none)."""
    mod = importlib.import_module(module_name)
    obj = getattr(mod, name)
    if inspect.isclass(obj):
        doc = obj.__doc__ or ""
        if is_dataclass(obj) and re.fullmatch(rf"{obj.__name__}\(.*\)", doc.strip(), re.S):
            return ""  # the signature dataclasses write
        return doc.strip()
    if inspect.isroutine(obj) or inspect.ismodule(obj):
        return (obj.__doc__ or "").strip()
    # a constant: its comment where it is defined (the module that re-exports it, or below)
    for where in _defining_modules(module_name):
        if text := _attr_doc(where, name):
            return text
    return ""


def _defining_modules(module_name: str) -> list[str]:
    """The module and its submodules, where a re-exported constant may be defined."""
    mod = importlib.import_module(module_name)
    out = [module_name]
    if hasattr(mod, "__path__"):
        subs = pkgutil.walk_packages(mod.__path__, module_name + ".")
        out += [m.name for m in subs if not m.name.endswith("__main__")]
    return out


def counts() -> tuple[int, list[str]]:
    """(number of public names, the undocumented ones as ``module.name``)."""
    names = public_names()
    total = sum(len(v) for v in names.values())
    missing = [f"{m}.{n}" for m, ns in names.items() for n in ns if not documentation(m, n)]
    return total, missing


def write_api_pages(out: Path) -> list[str]:
    """Write ``out/index.rst`` and one autosummary page per API module; return the pages."""
    out.mkdir(parents=True, exist_ok=True)
    pages = []
    for mod_name, names in public_names().items():
        title = f"``{mod_name}``"
        lines = [title, "=" * len(title), "", f".. automodule:: {mod_name}", "   :no-members:"]
        lines += ["   :no-index:", ""]  # bwdesign.certify is also a function
        lines += [f".. currentmodule:: {mod_name}", "", ".. autosummary::"]
        lines += ["   :toctree: generated", "   :nosignatures:", ""]
        lines += [f"   {n}" for n in names]
        page = mod_name.replace(".", "-")
        (out / f"{page}.rst").write_text("\n".join(lines) + "\n", encoding="utf-8")
        pages.append(page)
    index = [
        "API reference",
        "=============",
        "",
        "Generated from the numpydoc docstrings of every public name: ``bwdesign.__all__``",
        "(the names re-exported at the top level) and the ``__all__`` of each subpackage",
        "(a name that is also a top-level name is documented there once).",
        "",
        ".. toctree::",
        "   :maxdepth: 1",
        "",
    ] + [f"   {p}" for p in pages]
    (out / "index.rst").write_text("\n".join(index) + "\n", encoding="utf-8")
    return pages


if __name__ == "__main__":
    total, missing = counts()
    print(
        f"public names: {total}; documented: {total - len(missing)}; undocumented: {len(missing)}"
    )
    for m in missing:
        print(f"  undocumented: {m}")
