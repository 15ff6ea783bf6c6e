"""report.html in a real browser: headless Chromium via Selenium.

Skipped when Chromium or its driver is missing, except where
BWDESIGN_REQUIRE_BROWSER=1 (CI installs Debian's chromium and chromium-driver).
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import headless_chromium

from bwdesign.plotting.figures import plot_estimation_errors, save_figure
from bwdesign.report.document import Document

ROOT = Path(__file__).resolve().parents[1]
REPORTS = sorted((ROOT / "reports").glob("*/report.html"))


def _driver():
    return headless_chromium()


@pytest.fixture(scope="module")
def browser():
    drv = _driver()
    yield drv
    drv.quit()


#: Viewport widths the layout must fit without a horizontal scroll bar (laptop, half screen).
WIDTHS = (1280, 760)

_LAYOUT = """
const v = document.getElementById('verdict');
const pres = Array.from(document.querySelectorAll('pre')).map(p => {
  const cs = getComputedStyle(p);
  return [cs.whiteSpace, cs.overflowX, p.scrollWidth, p.clientWidth];
});
const summary = document.querySelector('#summary table');
return {
  verdict: v ? [v.className, v.textContent, getComputedStyle(v).backgroundColor] : null,
  pres: pres,
  page: [document.documentElement.scrollWidth, window.innerWidth],
  summary: summary ? Array.from(summary.rows).map(r => r.cells[0].textContent) : null,
};
"""


def _rgb(css: str) -> tuple[int, int, int]:
    r, g, b = (int(v) for v in re.findall(r"\d+", css)[:3])
    return r, g, b


def _layout(browser, html: Path, width: int) -> dict:
    browser.set_window_size(width, 1600)
    browser.get(html.as_uri())
    return browser.execute_script(_LAYOUT)


def _check_layout(out: dict, width: int) -> None:
    page, inner = out["page"]
    assert page <= inner, f"something is wider than a {width}-px window ({page} > {inner} px)"
    assert out["pres"], "no command block"
    for white_space, overflow_x, scroll, client in out["pres"]:
        # wrapped (nothing to scroll) or scrollable: never clipped
        assert white_space in ("pre-wrap", "break-spaces") or overflow_x in ("auto", "scroll")
        assert scroll <= client or overflow_x in ("auto", "scroll")


def _green(rgb: tuple[int, int, int]) -> bool:
    r, g, b = rgb
    return g > r + 10 and g > b + 5


def _red(rgb: tuple[int, int, int]) -> bool:
    r, g, b = rgb
    return r > g + 10 and r > b + 10


def _report_ok(cert: dict) -> bool:
    """The report's verdict flag, from its certificate.json."""
    c = cert["configured"]
    return (
        (c is None or c["certified"])
        and cert["synthesis"]["feasible"]
        and cert["input"]["within_limits"] is not False
    )


@pytest.mark.browser
@pytest.mark.parametrize("html", REPORTS, ids=[p.parent.name for p in REPORTS])
def test_report_renders_with_figures_and_certificate_table(browser, html):
    browser.set_window_size(1280, 2000)
    browser.get(html.as_uri())
    images = browser.execute_script(
        "return Array.from(document.images).map(i => [i.complete, i.naturalWidth, i.alt]);"
    )
    assert len(images) >= 5
    for complete, width, alt in images:
        assert complete and width > 100, f"figure did not load: {alt}"
    rows = browser.execute_script(
        "const t = document.getElementById('certificates');"
        "return t ? Array.from(t.tBodies[0].rows).map(r => r.cells[0].textContent) : null;"
    )
    assert rows == ["theorem1", "lipschitz", "sector", "sampled"]
    cert = json.loads((html.parent / "certificate.json").read_text())
    for width in WIDTHS:
        out = _layout(browser, html, width)
        _check_layout(out, width)
        assert out["verdict"], "no verdict element"
        cls, text, bg = out["verdict"]
        assert "CERTIFIED" in text
        ok = _report_ok(cert)
        assert (_green if ok else _red)(_rgb(bg)), (cls, bg, ok)
        assert out["summary"] == ["verdict", "envelope", "tracking (recommended loop)", "export"]


def _document(tmp_path: Path, ok: bool) -> Path:
    """A small report: verdict, summary, a wide table, a figure, a long command block."""
    (tmp_path / "figures").mkdir(parents=True)
    t = np.linspace(0, 1, 50)
    fig, _ = plot_estimation_errors({"x1 | PHSO (eq. 12)": (t, np.exp(-t))})
    save_figure(fig, tmp_path / "figures" / "e.png")
    doc = Document("verdict check")
    doc.verdict(("CERTIFIED: " if ok else "NOT CERTIFIED: ") + "the gains (8, 64, -512)", ok)
    doc.insert(1, _summary())
    doc.table([f"column {i}" for i in range(14)], [[f"value-{i}-{i * 7}" for i in range(14)]])
    doc.figure("figures/e.png", "an error figure")
    doc.pre(
        "# a command longer than any window\n"
        "bwdesign simulate --plant /a/very/long/path/"
        + "sub/" * 40
        + "stage.toml --gains "
        + ",".join(["786.2000000000001"] * 12)
    )
    html = tmp_path / "report.html"
    html.write_text(doc.to_html(tmp_path))
    return html


def _summary() -> Document:
    sub = Document("")
    sub.summary([["verdict", "**yes**"], ["export", "`bwdesign export-c --config x.toml`"]])
    return sub


@pytest.mark.browser
def test_verdict_is_green_or_red_and_nothing_is_clipped(browser, tmp_path):
    """Certified and not certified look different at a glance; command blocks wrap."""
    colours = {}
    for ok in (True, False):
        html = _document(tmp_path / str(ok), ok)
        for width in WIDTHS:
            out = _layout(browser, html, width)
            _check_layout(out, width)
            colours[ok] = _rgb(out["verdict"][2])
            assert out["summary"] == ["verdict", "export"]
    assert colours[True] != colours[False]
    assert _green(colours[True]) and _red(colours[False]), colours


def test_verdict_markdown_and_html_classes(tmp_path):
    """Markdown keeps the quoted verdict line; HTML marks it certified or not-certified."""
    for ok, cls in ((True, "verdict certified"), (False, "verdict not-certified")):
        doc = Document("t")
        doc.verdict("CERTIFIED: x" if ok else "NOT CERTIFIED: x", ok)
        doc.insert(1, _summary())
        md = doc.to_markdown().splitlines()
        assert md[2].startswith("> **") and md[4] == "## Summary"
        html = doc.to_html(tmp_path)
        assert f'<p id="verdict" class="{cls}" role="status">' in html
        assert html.index('id="verdict"') < html.index('id="summary"')


def test_reports_are_committed():
    """The generated reports are committed so a reader sees them without running anything."""
    names = {p.parent.name for p in REPORTS}
    assert {"paper_experiment", "paper_simulation_corrected", "stack_actuator_800hz"} <= names
