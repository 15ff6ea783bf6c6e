"""The package layout stays true: one direction of imports, heavy libraries in one place each.

Parses every module's imports with ``ast`` (imports inside functions count)
and checks the rules docs/guide/layout.md, section "Layout" states.
"""

from __future__ import annotations

import ast
import functools
from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "bwdesign"

#: Layers, lowest first: a layer imports only from layers below it (or itself).
#: ``errors``, ``_version``, ``validate``, ``interrupts``, ``memo``, ``output`` and
#: ``plotting`` import nothing above them;
#: ``plotting`` imports nothing from bwdesign at all, so any layer may call it.
LAYERS = (
    ("errors", "_version", "extras", "validate", "interrupts", "memo"),
    ("output", "plotting"),
    ("model",),
    ("identify",),
    ("observers",),
    ("control",),
    ("certify",),
    ("sim",),
    ("design",),  # above sim: the robust design simulates the box's corners
    ("codegen",),  # above design: export-c synthesises and tunes
    ("study",),
    ("report",),
    ("testing",),
    ("cli",),
)
RANK = {name: i for i, names in enumerate(LAYERS) for name in names}
#: Third-party packages allowed in one subpackage (or module) only (numba: in the two
#: compiled loops, each beside the Python it repeats, where ``make bench`` shows it earns it).
CONFINED = {
    "cvxpy": "bwdesign.certify.lmi",
    "matplotlib": "bwdesign.plotting",
    "dask": "bwdesign.sim.sweep",
    "numba": ("bwdesign.sim.compiled", "bwdesign.model.structural_compiled"),
}
#: The C templates are read only by code generation.
TEMPLATES_HOME = "bwdesign.codegen"
#: The API facade and the entry point may import anything.
FACADES = {"bwdesign", "bwdesign.__main__"}


def _module_name(path: Path, root: Path = PKG) -> str:
    rel = path.relative_to(root.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@functools.cache
def _parsed(path: Path) -> ast.Module:
    """The module's syntax tree, parsed once per run (several rules read every file;
    no rule changes a tree)."""
    return ast.parse(path.read_text(), str(path))


def _imports(path: Path, modules: set[str]) -> list[str]:
    """Absolute names of every module imported by ``path`` (function bodies included).

    ``from pkg import mod`` counts as an import of ``pkg.mod`` only (``pkg`` is
    then already being imported), ``from pkg import name`` as one of ``pkg``.
    """
    mod = _module_name(path)
    package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
    out = []
    for node in ast.walk(_parsed(path)):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            subs = [f"{target}.{a.name}" for a in node.names]
            out += subs if all(s in modules for s in subs) else [target]
    return out


def _graph() -> dict[str, set[str]]:
    files = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = defaultdict(set)
    for mod, path in files.items():
        graph[mod]
        for target in _imports(path, set(files)):
            if target in files and target != mod:
                graph[mod].add(target)
            elif target.split(".")[0] != "bwdesign":
                graph[mod].add("!" + target.split(".")[0])
    return graph


def _layer(mod: str) -> str | None:
    parts = mod.split(".")
    return parts[1] if len(parts) > 1 else None


@functools.cache
def _the_graph() -> dict[str, set[str]]:
    """:func:`_graph`, parsed once, when a test first reads it (not at collection, where
    every pytest-xdist worker would parse the package)."""
    return _graph()


class _Graph(Mapping):
    """The package's import graph (module -> imported modules), parsed on first use."""

    def __getitem__(self, mod: str) -> set[str]:
        return _the_graph()[mod]

    def __iter__(self):
        return iter(_the_graph())

    def __len__(self) -> int:
        return len(_the_graph())


GRAPH = _Graph()
#: The package's module names (the import graph's keys), from the file names alone.
MODULES = sorted(_module_name(p) for p in PKG.rglob("*.py"))


def test_every_subpackage_has_a_layer():
    layers = {_layer(m) for m in GRAPH} - {None, "__main__"}
    assert layers <= set(RANK), f"add {sorted(layers - set(RANK))} to LAYERS"


def _upward(mod: str, targets: set[str]) -> list[str]:
    """The imports of ``mod`` that go up the layers (or into the facade)."""
    if mod in FACADES:
        return []
    return sorted(
        t
        for t in targets
        if not t.startswith("!") and (t in FACADES or RANK[_layer(t)] > RANK[_layer(mod)])
    )


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                return stack[stack.index(t) :] + [t]
            if t not in state and (found := visit(t)):
                return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (found := visit(m)):
            return found
    return None


def test_the_module_names_are_the_graphs():
    assert MODULES == sorted(GRAPH)


@pytest.mark.parametrize("mod", MODULES)
def test_imports_go_down_the_layers(mod):
    bad = _upward(mod, GRAPH[mod])
    assert not bad, f"{mod} imports {bad}: against the direction of the layers"


def test_plotting_imports_nothing_from_bwdesign():
    for mod, targets in GRAPH.items():
        if _layer(mod) == "plotting":
            inner = [t for t in targets if not t.startswith("!") and _layer(t) != "plotting"]
            assert not inner, f"{mod} imports {inner}"


@pytest.mark.parametrize("library", sorted(CONFINED))
def test_heavy_libraries_are_confined(library):
    homes = CONFINED[library]
    homes = (homes,) if isinstance(homes, str) else homes
    users = [m for m, t in GRAPH.items() if "!" + library in t]
    assert users, f"nothing imports {library}: is the rule stale?"
    outside = [m for m in users if not any(m == h or m.startswith(h + ".") for h in homes)]
    assert not outside, f"{library} imported outside {homes}: {outside}"
    assert all(any(m == h or m.startswith(h + ".") for m in users) for h in homes), "stale home"


def test_no_import_cycle():
    graph = {m: {t for t in ts if not t.startswith("!")} for m, ts in GRAPH.items()}
    cycle = _find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_c_templates_are_read_only_by_codegen():
    readers = [
        _module_name(p)
        for p in PKG.rglob("*.py")
        if ".tmpl" in p.read_text() and not _module_name(p).startswith(TEMPLATES_HOME)
    ]
    assert not readers, f"C templates used outside {TEMPLATES_HOME}: {readers}"
    assert list((PKG / "codegen" / "templates").glob("*.tmpl")), "no templates: is the rule stale?"


def test_modules_stay_small():
    big = {
        str(p.relative_to(PKG)): n
        for p in PKG.rglob("*.py")
        if (n := len(p.read_text().splitlines())) > 900
    }
    assert not big, f"split along their concerns: {big}"


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _private_imports(path: Path, modules: set[str], root: Path = PKG) -> list[str]:
    """``target.name`` for every underscore name ``path`` takes from another bwdesign module.

    Counted: ``from X import _name`` and ``X._name`` where ``X`` is a name bound to
    an imported bwdesign module (function bodies included); dunder names are public.
    """
    mod = _module_name(path, root)
    package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
    tree = _parsed(path)
    bound: dict[str, str] = {}  # local name -> bwdesign module it is bound to
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "bwdesign":
                continue
            for a in node.names:
                full = f"{target}.{a.name}"
                if full in modules:
                    bound[a.asname or a.name] = full
                if _private(a.name) and target != mod:
                    out.append(full)
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.asname and a.name.split(".")[0] == "bwdesign":
                    bound[a.asname] = a.name
                elif a.name.split(".")[0] == "bwdesign":
                    bound["bwdesign"] = "bwdesign"
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            chain, value = [], node.value
            while isinstance(value, ast.Attribute):
                chain.append(value.attr)
                value = value.value
            if isinstance(value, ast.Name) and value.id in bound:
                target = ".".join([bound[value.id], *reversed(chain)])
                if target in modules and target != mod:
                    out.append(f"{target}.{node.attr}")
    return sorted(set(out))


FILES = {_module_name(p): p for p in PKG.rglob("*.py")}


@pytest.mark.parametrize("mod", sorted(FILES))
def test_no_underscore_name_is_imported_across_modules(mod):
    """A name another module needs is public at home (no leading underscore)."""
    bad = sorted(set(_private_imports(FILES[mod], set(FILES))))
    assert not bad, f"{mod} takes underscore names from other modules: {bad}; make them public"


#: Built-ins the package never raises itself: a typed error from errors.py subclasses them.
PLAIN = {"Exception", "ValueError", "RuntimeError", "TypeError"}


def _base_name(node: ast.expr) -> str:
    return node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")


def _exception_classes(tree: ast.AST) -> list[str]:
    """Classes whose bases name an exception or warning class (``...Error``, ``Exception``...)."""
    kinds = ("Error", "Exception", "Warning", "Interrupt", "Exit")
    return sorted(
        node.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ClassDef) and any(_base_name(b).endswith(kinds) for b in node.bases)
    )


def _plain_raises(tree: ast.AST) -> list[int]:
    """Lines of ``raise ValueError(...)`` (or another of :data:`PLAIN`, called or bare)."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Raise) and node.exc is not None:
            exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if _base_name(exc) in PLAIN:
                out.append(node.lineno)
    return sorted(out)


def test_every_exception_class_is_in_errors():
    trees = {m: _parsed(p) for m, p in FILES.items()}
    home = set(_exception_classes(trees["bwdesign.errors"]))
    assert {"SweepError", "UsageError", "TuningWarning", "InputError"} <= home
    for mod, tree in trees.items():
        if mod == "bwdesign.errors":
            continue
        found = _exception_classes(tree)
        assert not found, f"{mod} defines {found}: define them in bwdesign/errors.py"


def test_moved_exception_classes_stay_importable_where_they_were():
    from bwdesign import errors
    from bwdesign.cli.args import UsageError
    from bwdesign.control.controllers import TuningWarning
    from bwdesign.sim.sweep import SweepError

    assert (SweepError, UsageError, TuningWarning) == (
        errors.SweepError,
        errors.UsageError,
        errors.TuningWarning,
    )
    assert issubclass(SweepError, RuntimeError) and issubclass(UsageError, ValueError)
    assert not issubclass(errors.InternalError, errors.BWDesignError)


def test_no_plain_builtin_error_is_raised():
    bad = {mod: lines for mod, path in FILES.items() if (lines := _plain_raises(_parsed(path)))}
    assert not bad, f"raise a typed error from bwdesign/errors.py instead: {bad}"


def test_the_error_rules_can_fail():
    tree = ast.parse(
        "class A(errors.BWDesignError, ValueError): pass\n"
        "class B(UserWarning): pass\n"
        "class C: pass\n"
        "def f(x):\n"
        "    if x:\n"
        "        raise ValueError('no')\n"
        "    raise RuntimeError\n"
        "def g():\n"
        "    raise InputError('typed')\n"
    )
    assert _exception_classes(tree) == ["A", "B"]
    assert _plain_raises(tree) == [6, 7]


#: Most parameters and lines a public function (or public method) may have.
MAX_PARAMS, MAX_LINES = 10, 120


def _public_functions(mod: str, tree: ast.Module) -> list[tuple[str, ast.FunctionDef]]:
    """Module-level functions and the methods of module-level classes, without a leading _."""
    out = []
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            out.append((f"{mod}.{node.name}", node))
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            out += [
                (f"{mod}.{node.name}.{f.name}", f)
                for f in node.body
                if isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef)
            ]
    return [(name, f) for name, f in out if not f.name.startswith("_")]


def _over_limits(f: ast.FunctionDef) -> set[str]:
    """``"params"`` (more than MAX_PARAMS, self/cls not counted), ``"lines"`` (def to end)."""
    a = f.args
    params = [*a.posonlyargs, *a.args, *a.kwonlyargs, *filter(None, (a.vararg, a.kwarg))]
    if params and params[0].arg in ("self", "cls"):
        params = params[1:]
    over = set()
    if len(params) > MAX_PARAMS:
        over.add("params")
    if f.end_lineno - f.lineno + 1 > MAX_LINES:
        over.add("lines")
    return over


def test_public_functions_stay_within_the_limits():
    found: dict[str, set[str]] = {}
    for mod, path in FILES.items():
        for name, f in _public_functions(mod, _parsed(path)):
            if over := _over_limits(f):
                found[name] = over
    bad = {n: sorted(o) for n, o in found.items()}
    assert not bad, (
        f"over {MAX_PARAMS} parameters or {MAX_LINES} lines: {bad}; split the body into "
        "named helpers, group parameters that belong together"
    )


def test_the_limits_can_fail():
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_LINES))
    args = ", ".join(f"a{i}" for i in range(MAX_PARAMS))
    tree = ast.parse(
        f"def long():\n{body}\n"
        f"def wide({args}, *, extra): pass\n"
        f"def fine({args}): pass\n"
        f"def _private({args}, more): pass\n"
        f"class C:\n    def method(self, {args}): pass\n    def wide(self, {args}, b): pass\n"
    )
    funcs = dict(_public_functions("m", tree))
    assert set(funcs) == {"m.long", "m.wide", "m.fine", "m.C.method", "m.C.wide"}
    assert {n: _over_limits(f) for n, f in funcs.items()} == {
        "m.long": {"lines"},
        "m.wide": {"params"},
        "m.fine": set(),
        "m.C.method": set(),
        "m.C.wide": {"params"},
    }


def test_the_checks_can_fail():
    """The rules catch what they are for: an upward import, a cycle, a function-level import."""
    assert _upward("bwdesign.model.params", {"bwdesign.cli.main"}) == ["bwdesign.cli.main"]
    assert _upward("bwdesign.sim.result", {"bwdesign.report.certified"})
    assert _upward("bwdesign.sim.result", {"bwdesign"}) == ["bwdesign"]
    assert not _upward("bwdesign.report.certified", {"bwdesign.sim.result", "!numpy"})
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    # write_report imports the figures inside a function: the graph sees it
    assert "bwdesign.plotting.figures" in GRAPH["bwdesign.report.certified"]


def test_the_underscore_rule_can_fail(tmp_path):
    """Both spellings are caught, in function bodies too; dunders and own names are not."""
    pkg = tmp_path / "bwdesign"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "home.py").write_text("_x = 1\n__version__ = '1'\n")
    (pkg / "sub" / "user.py").write_text(
        "from . import home\n"
        "from .home import __version__\n"
        "from bwdesign.sub.home import _x as y\n"
        "_own = 2\n"
        "def f():\n"
        "    import bwdesign.sub.home as h\n"
        "    import bwdesign.sub.home\n"
        "    return home._x + h._y + bwdesign.sub.home._z + _own\n"
    )
    modules = {"bwdesign.sub", "bwdesign.sub.home", "bwdesign.sub.user"}
    found = _private_imports(pkg / "sub" / "user.py", modules, root=pkg)
    assert found == ["bwdesign.sub.home._x", "bwdesign.sub.home._y", "bwdesign.sub.home._z"]
