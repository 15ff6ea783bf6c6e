"""The public names the API reference documents, and which of them have no documentation.

The public API is ``bwdesign.__all__`` (re-exported name by name in
``bwdesign/__init__.py``) and the ``__all__`` of each subpackage. ``conf.py`` writes
one autosummary page per module from this list at build time, and
``tests/test_api_docs.py`` checks that every name has a docstring (or, for a
constant, a ``#:`` comment, which autodoc shows).

Run ``python docs/api_names.py`` for the counts.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import pkgutil
import re
from dataclasses import is_dataclass
from pathlib import Path

#: Subpackages that are not a library API: the command line has one entry point.
NOT_API = {"bwdesign.cli", "bwdesign.__main__"}
#: Modules documented beside the subpackages: the Python side of a command the guide
#: shows (``bwdesign sweep``, ``bwdesign excite``), whose names their package does not
#: re-export.
EXTRA_MODULES = ("bwdesign.sim.sweep", "bwdesign.identify.excite")


def api_modules() -> list[str]:
    """``bwdesign``, every subpackage with an ``__all__`` and :data:`EXTRA_MODULES`.

    The rest of a module's contents may change (``bwdesign/__init__.py``: the public
    API is what the packages re-export), so the reference leaves them out.
    """
    import bwdesign

    names = ["bwdesign"]
    for m in pkgutil.walk_packages(bwdesign.__path__, "bwdesign."):
        if m.ispkg and m.name not in NOT_API:
            if getattr(importlib.import_module(m.name), "__all__", None):
                names.append(m.name)
    return names + list(EXTRA_MODULES)


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


@functools.cache
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
    # a constant: its comment where it is defined (this module, or the one it came from)
    for where in [module_name, *_all_modules()]:
        other = importlib.import_module(where)
        if getattr(other, name, None) is obj and (text := _attr_doc(where, name)):
            return text
    return ""


@functools.cache
def _all_modules() -> tuple[str, ...]:
    """Every module of the package but the command line's entry point."""
    import bwdesign

    found = pkgutil.walk_packages(bwdesign.__path__, "bwdesign.")
    return tuple(m.name for m in found if not m.name.endswith("__main__"))


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
        _count_sentence(),
        "",
        ".. toctree::",
        "   :maxdepth: 1",
        "",
    ] + [f"   {p}" for p in pages]
    (out / "index.rst").write_text("\n".join(index) + "\n", encoding="utf-8")
    return pages


def _count_sentence() -> str:
    """The counts as one sentence for the reference's index page."""
    total, missing = counts()
    text = f"This build documents {total - len(missing)} of {total} public names"
    if missing:
        return text + "; without documentation: " + ", ".join(f"``{m}``" for m in missing) + "."
    return text + "; none is without documentation."


if __name__ == "__main__":
    total, missing = counts()
    print(
        f"public names: {total}; documented: {total - len(missing)}; undocumented: {len(missing)}"
    )
    for m in missing:
        print(f"  undocumented: {m}")
