"""Sphinx configuration of the bwdesign documentation (``make docs``).

``make docs`` copies ``docs/`` into ``docs/_build/src`` and builds from there, so
everything the build generates (the API pages, the gallery's pages and figures) stays
under ``docs/_build/``. The API pages come from ``api_names.py``; the gallery runs every
script of ``examples/gallery/``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _repository_root() -> Path:
    """The checkout: the first parent with pyproject.toml (docs/ or docs/_build/src)."""
    for parent in [HERE, *HERE.parents]:
        if (parent / "pyproject.toml").is_file() and (parent / "bwdesign").is_dir():
            return parent
    raise RuntimeError(f"no bwdesign checkout above {HERE}")


ROOT = _repository_root()
sys.path.insert(0, str(HERE))
os.environ.setdefault("MPLBACKEND", "Agg")

import api_names  # noqa: E402

import bwdesign  # noqa: E402

api_names.write_api_pages(HERE / "api")


def _starter() -> None:
    """guide/starter.toml: the file ``bwdesign init`` writes, shown by the stage-files page."""
    import contextlib
    import io

    from bwdesign.cli import main

    target = HERE / "guide" / "starter.toml"
    if target.exists():
        return
    with contextlib.redirect_stdout(io.StringIO()) as said:
        code = main(["init", str(target)])
    if code != 0:
        raise RuntimeError(f"bwdesign init failed ({code}): {said.getvalue()}")


_starter()

project = "bwdesign"
author = "bwdesign maintainers"
copyright = "bwdesign maintainers, MIT licence"  # noqa: A001
release = bwdesign.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "**/*.zip"]
templates_path = ["_templates"]

# MyST: headings get anchors (docs/design.md is cited by heading), $...$ math, tables
myst_heading_anchors = 4
myst_enable_extensions = ["dollarmath", "colon_fence"]

autosummary_generate = True
autosummary_imported_members = True
autodoc_default_options = {"members": True, "inherited-members": False, "show-inheritance": True}
autodoc_typehints = "none"  # numpydoc's Parameters sections say the types
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

html_theme = "furo"
html_title = f"bwdesign {release}"
html_static_path = []

sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples" / "gallery"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",  # every plot_*.py runs during the build
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "image_scrapers": ("matplotlib",),
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "reset_modules": ("matplotlib",),
}
