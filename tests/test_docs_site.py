"""The built documentation site (``make docs``) renders and links only to files it has.

Every internal link (``href``/``src`` of every page, external ones and anchors within
a page skipped) must name a file of ``docs/_build/html``, and the index and a gallery
page must render in headless Chromium: a title, no Sphinx system message, no
traceback from a gallery script, and every image loaded.

Skipped without the built site or without Chromium, except where
BWDESIGN_REQUIRE_BROWSER=1: CI builds the site (``make docs`` in ``.ci/run``) and
installs Debian's chromium and chromium-driver, so there both must run.
"""

from __future__ import annotations

import os
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest
from conftest import headless_chromium

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "docs/_build/html"
REQUIRED = os.environ.get("BWDESIGN_REQUIRE_BROWSER") == "1"
#: Text that only a broken page shows (a failed gallery script, a docutils error).
BROKEN = ("Traceback (most recent call last)", "System Message", "Unknown directive")


def _site() -> Path:
    if not (SITE / "index.html").is_file():
        if REQUIRED:
            pytest.fail(f"BWDESIGN_REQUIRE_BROWSER=1 but {SITE} is not built (make docs)")
        pytest.skip("the documentation is not built (make docs)")
    return SITE


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links: list[str] = []

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if name in ("href", "src") and value:
                self.links.append(value)


def internal_links(page: Path) -> list[str]:
    """The page's links to files of the site (no scheme, not only an anchor)."""
    parser = _Links()
    parser.feed(page.read_text(encoding="utf-8"))
    out = []
    for link in parser.links:
        parts = urlsplit(link)
        if parts.scheme or parts.netloc or not parts.path:
            continue  # external (https:, mailto:, data:, //host) or an anchor in the page
        out.append(unquote(parts.path))
    return out


def broken_links(site: Path) -> list[str]:
    """``page: link`` for every internal link that names no file of the site."""
    found = []
    for page in sorted(site.rglob("*.html")):
        for link in internal_links(page):
            target = (page.parent / link).resolve()
            if target.is_dir():
                target = target / "index.html"
            if not (target.is_relative_to(site) and target.is_file()):
                found.append(f"{page.relative_to(site)}: {link}")
    return found


def test_broken_links_are_found(tmp_path):
    """The link check is not idle: a missing page, an escape and a good link."""
    (tmp_path / "a.html").write_text(
        '<a href="b.html#x">b</a><a href="missing.html">m</a><img src="../out.png">'
        '<a href="https://example.org/x.html">e</a><a href="#top">t</a>',
        encoding="utf-8",
    )
    (tmp_path / "b.html").write_text("<p>b</p>", encoding="utf-8")
    assert broken_links(tmp_path) == ["a.html: missing.html", "a.html: ../out.png"]


@pytest.mark.browser
def test_every_internal_link_resolves():
    site = _site()
    pages = list(site.rglob("*.html"))
    assert len(pages) > 20 and (site / "api/index.html").is_file()
    bad = broken_links(site)
    assert not bad, f"{len(bad)} internal links name no file:\n" + "\n".join(bad[:40])


def _driver():
    return headless_chromium()


_STATE = """
return {
  title: document.title,
  text: document.body.innerText,
  images: Array.from(document.images).map(
    i => [i.getAttribute('src'), i.complete && i.naturalWidth > 0]),
  system_messages: document.querySelectorAll('.system-message').length,
  nav: document.querySelectorAll('a').length,
};
"""


@pytest.mark.browser
@pytest.mark.parametrize(
    "page, heading",
    [("index.html", "bwdesign"), ("auto_examples/plot_observer_filterpy.html", "filterpy")],
    ids=["index", "gallery-page"],
)
def test_pages_render_in_chromium(page, heading):
    site = _site()
    driver = _driver()
    try:
        driver.get((site / page).as_uri())
        state = driver.execute_script(_STATE)
    finally:
        driver.quit()
    assert "bwdesign" in state["title"] and heading in state["title"], state["title"]
    assert state["system_messages"] == 0
    assert not [b for b in BROKEN if b in state["text"]], state["text"][:2000]
    assert state["nav"] > 10  # the theme's navigation is there
    not_loaded = [src for src, ok in state["images"] if not ok]
    assert not not_loaded, f"images that did not load: {not_loaded}"
    if page.startswith("auto_examples/"):
        figures = [src for src, _ in state["images"] if "sphx_glr_" in (src or "")]
        assert figures, "the gallery page shows no figure of its script"


def test_the_gallery_has_runnable_examples():
    """At least eight gallery scripts, each with the title sphinx-gallery needs."""
    scripts = sorted((ROOT / "examples/gallery").glob("plot_*.py"))
    assert len(scripts) >= 8, scripts
    for script in scripts:
        head = script.read_text(encoding="utf-8").lstrip().splitlines()[:3]
        assert head[0] == '"""' and set(head[2]) == {"="}, script.name
