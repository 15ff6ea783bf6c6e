"""The design document is in the repository, and everything cites what the repository holds.

``docs/design.md`` is the package's design document. Docstrings, comments and
documents cite it (and other Markdown files) as ``PATH, section "Heading"``. These
tests fail when

- a file of the repository cites a file outside it (the design notes, style notes or
  paper that once lived beside the repository, an absolute path of a machine, a
  Markdown link that leaves the repository);
- a citation names a Markdown file or a section that does not exist, or a section by
  number instead of by name, or the package cites the design document without a
  section;
- the design document names a file, or a name in a file, that does not exist, or its
  table of the current layers differs from ``LAYERS`` in ``tests/test_layout.py``.
"""

from __future__ import annotations

import ast
import re
import subprocess
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "docs/design.md"
#: Directories never scanned when the repository is not a git checkout.
SKIP_DIRS = {".git", ".venv", "venv", "build", "dist", "__pycache__", ".pytest_cache"}
SKIP_DIRS |= {".ruff_cache", ".hypothesis", "node_modules"}
#: Strings that point outside the repository (written so this file does not match them).
OUTSIDE = (
    (re.compile(r"\.\./shared"), "a path into a shared folder beside the repository"),
    (re.compile(r"(?<![\w.])/wor[k]/"), "an absolute path of a build machine"),
    (re.compile(r"shared/pape[r]"), "the paper's copy outside the repository"),
    (re.compile(r"zhao2024_bouc_we[n]"), "the paper's file outside the repository"),
    (re.compile(r"\bSTYLE\.md"), "style notes outside the repository"),
)
#: What may follow a Markdown file's path: ``, section "Name"`` (a closing backtick and
#: line breaks allowed), ``, section 3`` (refused: numbers change) or ``#anchor``.
SECTION = re.compile(r'`?,?\s+section\s+"(?P<name>[^"]+)"')
NUMBERED = re.compile(r"`?,?\s+section\s+\d")
ANCHOR = re.compile(r"#(?P<anchor>[\w-]+)")
#: Characters of a path.
PATH_CHARS = re.compile(r"[\w./-]*\Z")
#: A relative Markdown link ``](target)``.
LINK = re.compile(r"\]\((?P<target>[^)\s]+)\)")
#: Paths the design document names in backticks.
DOC_PATH = re.compile(
    r"`((?:bwdesign|tests|reports|analysis|docs|configs|examples|benchmarks)/[^`\s]*)`"
)
#: ``NAME` in `FILE``: a name the design document says a file defines.
DOC_NAME = re.compile(r"`([A-Za-z_][\w.]*)(?:\(\))?` in `([\w./-]+\.py)`")


def repository_files() -> list[Path]:
    """Every file of the repository: tracked and new ones, not ignored ones."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT,
            capture_output=True,
            check=True,
            timeout=60,
        ).stdout.decode()
        names = [n for n in out.split("\0") if n]
    except (OSError, subprocess.SubprocessError):
        names = [
            str(p.relative_to(ROOT))
            for p in ROOT.rglob("*")
            if not SKIP_DIRS & set(p.relative_to(ROOT).parts)
        ]
    files = [ROOT / n for n in names]
    return sorted(p for p in files if p.is_file() and not p.is_symlink())


@cache
def text_of(path: Path) -> str | None:
    """The file's text, or None for a binary file."""
    data = path.read_bytes()
    if b"\0" in data:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


def text_files() -> list[tuple[str, str]]:
    out = []
    for p in repository_files():
        text = text_of(p)
        if text is not None:
            out.append((str(p.relative_to(ROOT)), text))
    return out


def slug(heading: str) -> str:
    """The anchor GitHub and MyST give a heading."""
    s = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return s.replace(" ", "-")


def headings(text: str) -> list[str]:
    """ATX headings of a Markdown text (outside fenced code), whitespace normalised."""
    out, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
        elif not fenced and (m := re.match(r"#{1,6}\s+(.+?)\s*#*\s*$", line)):
            out.append(" ".join(m.group(1).split()))
    return out


def outside_citations(where: str, text: str) -> list[str]:
    """Places in ``text`` (the file ``where``) that cite something outside the repository."""
    found = []
    for pattern, what in OUTSIDE:
        found += [f"{where}: {m.group(0)!r}: {what}" for m in pattern.finditer(text)]
    in_docs = where.startswith("docs/")
    for m in re.finditer(r"design\.md", text, re.IGNORECASE):
        before = text[max(0, m.start() - 5) : m.start()]
        relative = in_docs and not re.search(r"[\w./-]$", before)  # a link within docs/
        if m.group(0).islower() and (before == "docs/" or relative):
            continue
        found.append(f"{where}: {text[max(0, m.start() - 20) : m.end()]!r}: cite docs/design.md")
    if where.endswith(".md"):
        base = (ROOT / where).parent
        for m in LINK.finditer(text):
            target = m.group("target").split("#")[0]
            if not target or re.match(r"[a-z][a-z0-9+.-]*:", target):
                continue  # an anchor in the same file, or a URL
            resolved = (base / target).resolve()
            if not resolved.is_relative_to(ROOT):
                found.append(f"{where}: link {target!r} leaves the repository")
            elif not resolved.exists():
                found.append(f"{where}: link {target!r} does not exist")
    return found


def md_references(text: str) -> list[tuple[str, int, int]]:
    """Every ``PATH.md`` in ``text``: (path, start, end); found by the literal, so fast."""
    out, at = [], text.find(".md")
    while at >= 0:
        end = at + 3
        if end == len(text) or not re.match(r"[\w]", text[end]):
            start = at - len(PATH_CHARS.search(text, max(0, at - 300), at).group(0))
            if start < at:
                out.append((text[start:end], start, end))
        at = text.find(".md", end)
    return out


def citation_problems(where: str, text: str) -> list[str]:
    """Citations of a Markdown file or a section that does not exist."""
    found = []

    def headings_of(path: str) -> list[str] | None:
        target = (ROOT / path.removeprefix("./")).resolve()
        if not (target.is_relative_to(ROOT) and target.is_file()):
            return None
        return headings(text_of(target) or "")

    for path, _, end in md_references(text):
        if m := SECTION.match(text, end):
            name = " ".join(m.group("name").split())
            heads = headings_of(path)
            if heads is None:
                found.append(f"{where}: cites {path}, which is not in the repository")
            elif name not in heads:
                found.append(f"{where}: cites section {name!r} of {path}: no such heading")
        elif m := NUMBERED.match(text, end):
            found.append(f"{where}: {path + m.group(0)!r}: cite a section by its heading")
        elif m := ANCHOR.match(text, end):
            heads = headings_of(path) or []
            if m.group("anchor") not in {slug(h) for h in heads}:
                found.append(f"{where}: {path + m.group(0)!r}: no such file or heading")
        elif path == "docs/design.md" and where.startswith("bwdesign/"):
            # the package's docstrings and stage files name the section they rely on
            found.append(f"{where}: cites docs/design.md without a section")
    return found


def test_the_design_document_is_in_the_repository():
    heads = headings(DESIGN.read_text(encoding="utf-8"))
    assert heads[0] == "The design of bwdesign"
    duplicates = sorted({h for h in heads if heads.count(h) > 1})
    assert not duplicates, f"headings must be unique to be cited: {duplicates}"


def test_nothing_cites_a_file_outside_the_repository():
    found = [f for where, text in text_files() for f in outside_citations(where, text)]
    assert not found, "\n".join(found)


def test_every_cited_section_exists():
    """Every citation of a Markdown file names a file and a heading that exist.

    This file is left out: its examples below are wrong on purpose.
    """
    this = str(Path(__file__).resolve().relative_to(ROOT))
    found = [
        f for where, text in text_files() if where != this for f in citation_problems(where, text)
    ]
    assert not found, "\n".join(found)


def test_the_package_cites_the_design_document():
    """The docstrings that need the design document cite it (the checks above are not idle)."""
    citing = [
        where
        for where, text in text_files()
        if where.startswith("bwdesign/")
        and any(SECTION.match(text, end) for _, _, end in md_references(text))
    ]
    assert "bwdesign/certify/tiers.py" in citing and "bwdesign/model/plant.py" in citing


def test_the_design_document_names_what_exists():
    text = DESIGN.read_text(encoding="utf-8")
    missing = [
        p
        for p in DOC_PATH.findall(text)
        if not (list(ROOT.glob(p)) if "*" in p else (ROOT / p).exists())
    ]
    assert not missing, f"docs/design.md names files that do not exist: {missing}"
    absent = [
        f"{name} in {path}"
        for name, path in DOC_NAME.findall(text)
        if not (ROOT / path).is_file()
        or not re.search(rf"\b{re.escape(name.split('.')[-1])}\b", (ROOT / path).read_text())
    ]
    assert not absent, f"docs/design.md names what the files do not define: {absent}"


def _layers_in_force() -> list[tuple[str, ...]]:
    tree = ast.parse((ROOT / "tests/test_layout.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "LAYERS" for t in node.targets
        ):
            return [tuple(layer) for layer in ast.literal_eval(node.value)]
    raise AssertionError("tests/test_layout.py defines no LAYERS")


def _layers_in_design() -> list[tuple[str, ...]]:
    text = DESIGN.read_text(encoding="utf-8")
    section = text.split("### Current layers", 1)[1].split("\n#", 1)[0]
    rows = re.findall(r"^\| (\d+) \| ([^|]+) \|", section, re.MULTILINE)
    assert [int(rank) for rank, _ in rows] == list(range(len(rows))), rows
    return [tuple(re.findall(r"`(\w+)`", names)) for _, names in rows]


def test_the_design_document_states_the_layers_in_force():
    assert _layers_in_design() == _layers_in_force()


@pytest.mark.parametrize(
    "text, found",
    [
        ("see DESIGN" + ".md section 3", "cite docs/design.md"),
        ("notes in .." + "/shared/notes", "shared folder"),
        ("the paper, /" + "work/paper.md", "absolute path"),
        ("see the STYLE" + ".md", "style notes"),
        ("[paper](../../paper.md)", "leaves the repository"),
        ("[fig](figures/none.png)", "does not exist"),
    ],
    ids=["design-notes", "shared", "absolute", "style", "link-out", "link-missing"],
)
def test_outside_citations_are_caught(text, found):
    problems = outside_citations("notes/example.md", text)
    assert any(found in p for p in problems), problems


@pytest.mark.parametrize(
    "text, found",
    [
        ('see docs/design.md, section "No such section"', "no such heading"),
        ('see docs/design.md, section\n    "No such\n    section"', "no such heading"),
        ('see docs/nothing.md, section "The model"', "not in the repository"),
        ("see docs/design.md section 3", "by its heading"),
        ("see docs/design.md#no-such-anchor", "no such file or heading"),
        ("see docs/design.md for the model", "without a section"),
    ],
    ids=["section", "wrapped", "file", "numbered", "anchor", "bare"],
)
def test_citation_problems_are_caught(text, found):
    problems = citation_problems("bwdesign/example.py", text)
    assert any(found in p for p in problems), problems


def test_valid_citations_pass():
    good = (
        'docs/design.md, section "Exact sampling"; (`docs/design.md`, section "The\n'
        '    sample clock"); docs/design.md#the-model; docs/guide/layout.md, section "Layout"'
    )
    assert citation_problems("bwdesign/example.py", good) == []
    assert outside_citations("bwdesign/example.py", good) == []
