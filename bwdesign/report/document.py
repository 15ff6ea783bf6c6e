"""A small document model rendered to Markdown and to self-contained HTML.

Reports are built once as a list of blocks (headings, paragraphs, tables,
figures, preformatted text) and rendered twice, so the Markdown and the HTML
say the same thing. The HTML embeds figures as base64 data URIs: one file, no
network.
"""

from __future__ import annotations

import base64
import html
from dataclasses import dataclass, field
from pathlib import Path

from ..output.text import fmt

__all__ = ["Document", "fmt"]


@dataclass
class Document:
    """Blocks of a report, in order.

    Figures are referenced by a path relative to the report directory and read
    from ``root`` when the HTML is rendered.
    """

    title: str
    blocks: list[tuple[str, object]] = field(default_factory=list)

    def heading(self, text: str, level: int = 2) -> None:
        self.blocks.append(("h", (level, text)))

    def para(self, text: str) -> None:
        self.blocks.append(("p", text))

    def callout(self, text: str) -> None:
        """A highlighted paragraph (a note that is not a verdict)."""
        self.blocks.append(("callout", text))

    def verdict(self, text: str, ok: bool) -> None:
        """The verdict at the top: green in HTML when ``ok``, red when not (``id="verdict"``)."""
        self.blocks.append(("verdict", (text, bool(ok))))

    def summary(self, rows: list[list[str]]) -> None:
        """A short item/value block read before the rest (``id="summary"`` in HTML)."""
        self.blocks.append(("summary", [list(map(str, r)) for r in rows]))

    def insert(self, at: int, other: Document) -> None:
        """Put ``other``'s blocks before block ``at`` (e.g. a summary built at the end)."""
        self.blocks[at:at] = other.blocks

    def bullets(self, items: list[str]) -> None:
        self.blocks.append(("ul", list(items)))

    def table(self, header: list[str], rows: list[list[str]], *, id: str = "") -> None:
        self.blocks.append(("table", (header, [list(map(str, r)) for r in rows], id)))

    def figure(self, path: str, caption: str) -> None:
        self.blocks.append(("fig", (path, caption)))

    def pre(self, text: str) -> None:
        self.blocks.append(("pre", text))

    # -- rendering ----------------------------------------------------------
    def to_markdown(self) -> str:
        out = [f"# {self.title}", ""]
        for kind, data in self.blocks:
            if kind == "h":
                level, text = data
                out += ["#" * level + " " + text, ""]
            elif kind == "p":
                out += [data, ""]
            elif kind == "callout":
                out += [f"> **{data}**", ""]
            elif kind == "verdict":
                out += [f"> **{data[0]}**", ""]
            elif kind == "summary":
                out += ["## Summary", "", "| item | value |", "|---|---|"]
                out += [f"| {_cell(k)} | {_cell(v)} |" for k, v in data] + [""]
            elif kind == "ul":
                out += [f"- {item}" for item in data] + [""]
            elif kind == "table":
                header, rows, _ = data
                out.append("| " + " | ".join(_cell(h) for h in header) + " |")
                out.append("|" + "|".join("---" for _ in header) + "|")
                out += ["| " + " | ".join(_cell(c) for c in r) + " |" for r in rows]
                out.append("")
            elif kind == "fig":
                path, caption = data
                out += [f"![{caption}]({path})", "", f"*{caption}*", ""]
            elif kind == "pre":
                out += ["```", data.rstrip("\n"), "```", ""]
        return "\n".join(out).rstrip("\n") + "\n"

    def to_html(self, root: Path) -> str:
        e = html.escape
        body = [f"<h1>{e(self.title)}</h1>"]
        for kind, data in self.blocks:
            if kind == "h":
                level, text = data
                body.append(f"<h{level}>{e(text)}</h{level}>")
            elif kind == "p":
                body.append(f"<p>{_inline(data)}</p>")
            elif kind == "callout":
                body.append(f'<p class="callout">{_inline(data)}</p>')
            elif kind == "verdict":
                text, ok = data
                cls = "certified" if ok else "not-certified"
                body.append(
                    f'<p id="verdict" class="verdict {cls}" role="status">{_inline(text)}</p>'
                )
            elif kind == "summary":
                trs = "".join(
                    f'<tr><th scope="row">{_inline(k)}</th><td>{_inline(v)}</td></tr>'
                    for k, v in data
                )
                body.append(
                    f'<section id="summary"><h2>Summary</h2><table class="summary">'
                    f"<tbody>{trs}</tbody></table></section>"
                )
            elif kind == "ul":
                body.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in data) + "</ul>")
            elif kind == "table":
                header, rows, tid = data
                attr = f' id="{e(tid)}"' if tid else ""
                head = "".join(f"<th>{_inline(h)}</th>" for h in header)
                trs = "".join(
                    "<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in r) + "</tr>" for r in rows
                )
                body.append(
                    f'<div class="table-wrap"><table{attr}><thead><tr>{head}</tr></thead>'
                    f"<tbody>{trs}</tbody></table></div>"
                )
            elif kind == "fig":
                path, caption = data
                b64 = base64.b64encode((root / path).read_bytes()).decode("ascii")
                body.append(
                    f'<figure><img src="data:image/png;base64,{b64}" alt="{e(caption)}">'
                    f"<figcaption>{e(caption)}</figcaption></figure>"
                )
            elif kind == "pre":
                body.append(f"<pre>{e(data)}</pre>")
        return _PAGE.format(title=e(self.title), body="\n".join(body))


def _cell(text: str) -> str:
    """A Markdown table cell: pipes escaped so ``|u'|`` does not split the cell."""
    return text.replace("|", "\\|")


def _inline(text: str) -> str:
    """Escape, then render the two inline marks reports use: **bold** and `code`."""
    out, bold, code = [], False, False
    i = 0
    s = html.escape(text)
    while i < len(s):
        if s.startswith("**", i) and not code:
            out.append("</strong>" if bold else "<strong>")
            bold = not bold
            i += 2
        elif s[i] == "`":
            out.append("</code>" if code else "<code>")
            code = not code
            i += 1
        else:
            out.append(s[i])
            i += 1
    if bold:
        out.append("</strong>")
    if code:
        out.append("</code>")
    return "".join(out)


_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
body {{ font-family: system-ui, sans-serif; max-width: 60rem; margin: 2rem auto;
       padding: 0 1rem; line-height: 1.45; color: #222; }}
.table-wrap {{ max-width: 100%; overflow-x: auto; }}
table {{ border-collapse: collapse; margin: 1rem 0; font-size: 0.92rem; }}
th, td {{ border: 1px solid #bbb; padding: 0.25rem 0.5rem; text-align: left; }}
th {{ background: #eee; }}
figure {{ margin: 1rem 0; }}
figure img {{ max-width: 100%; height: auto; }}
figcaption {{ font-style: italic; font-size: 0.9rem; }}
pre {{ background: #f5f5f5; padding: 0.5rem; white-space: pre-wrap;
      overflow-wrap: anywhere; overflow-x: auto; }}
code {{ background: #f5f5f5; padding: 0 0.2rem; overflow-wrap: anywhere; }}
.callout {{ border-left: 4px solid #c60; padding: 0.5rem 1rem; background: #fff6ee; }}
.verdict {{ border-left: 8px solid; padding: 0.75rem 1rem; font-size: 1.05rem; }}
.verdict.certified {{ border-color: #1b7f3b; background: #e3f4e8; color: #0d3d1c; }}
.verdict.not-certified {{ border-color: #b3261e; background: #fbe4e2; color: #5c0f0a; }}
#summary h2 {{ margin-bottom: 0.25rem; }}
table.summary {{ width: 100%; }}
table.summary th {{ width: 14rem; vertical-align: top; }}
</style>
</head>
<body>
{body}
</body>
</html>
"""
