"""Every ``Examples`` section of the package's docstrings runs, as written (doctest).

The numpydoc ``Examples`` sections are the package's smallest usage examples; this
runs each module's doctests in the default suite, so an example that no longer works
fails here rather than in a user's hands. An ``Examples`` section without a ``>>>``
line would never run: that fails too.
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import pkgutil
import re

import pytest

import bwdesign

#: Modules that are entry points, not libraries (importing ``__main__`` runs the CLI).
SKIP = {"bwdesign.__main__"}
MODULES = sorted(
    m.name for m in pkgutil.walk_packages(bwdesign.__path__, "bwdesign.") if m.name not in SKIP
)
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
#: A numpydoc ``Examples`` heading and the text of its section (up to the next heading).
EXAMPLES = re.compile(
    r"^\s*Examples\n\s*-{8,}\n(?P<body>.*?)(?=^\s*\w[\w ]*\n\s*-{3,}\n|\Z)", re.M | re.S
)


def _docstrings(module) -> list[tuple[str, str]]:
    """(qualified name, docstring) of the module and everything it defines."""
    finder = doctest.DocTestFinder(exclude_empty=False)
    return [(t.name, t.docstring or "") for t in finder.find(module, module.__name__)]


@pytest.mark.parametrize("name", MODULES)
def test_module_examples_run(name):
    module = importlib.import_module(name)
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    finder = doctest.DocTestFinder()
    for test in finder.find(module, name):
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed"


def test_every_examples_section_has_code():
    empty = []
    for name in MODULES:
        module = importlib.import_module(name)
        for qualname, doc in _docstrings(module):
            for m in EXAMPLES.finditer(inspect.cleandoc(doc)):
                if ">>>" not in m.group("body"):
                    empty.append(qualname)
    assert not empty, f"Examples sections that run nothing: {empty}"


def test_the_package_has_examples():
    """The collection is not idle: the package's examples are found and counted."""
    total = 0
    for name in MODULES:
        module = importlib.import_module(name)
        total += sum(len(t.examples) for t in doctest.DocTestFinder().find(module, name))
    assert total >= 70, total
