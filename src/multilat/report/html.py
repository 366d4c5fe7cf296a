"""A small, escaped HTML report: sections of paragraphs, tables and embedded PNG figures.

Numbers that come from a command's JSON document are written as :class:`Num` cells: the cell
carries the JSON path it was read from, the scale and coverage factor applied to it, so that a test
(and a reader with the browser's inspector) can check every printed number against the JSON.
"""

from __future__ import annotations

import base64
import html
import io
import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Num:
    """A number shown in a table cell: ``value * k * scale`` (after ``op``) to ``digits`` decimals.

    ``path`` is where ``value`` sits in the command's JSON document (keys and list indices joined by
    ``/``); ``op`` is ``""``, ``"sqrt"`` (a standard deviation from a variance) or ``"inv"`` (the
    reciprocal: the lower bound ``1/f`` of a band ``[1/f, f]``).
    """

    value: float | None
    path: str = ""
    scale: float = 1.0
    digits: int = 2
    k: float = 1.0
    op: str = ""
    sign: bool = False

    def text(self) -> str:
        v = self.value
        if v is None or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            return "-" if v is None else str(v)
        v = float(v)
        if self.op == "sqrt":
            v = math.sqrt(max(v, 0.0))
        elif self.op == "inv":
            v = 1.0 / v if v != 0 else math.inf
        v = v * self.k * self.scale
        if round(v, self.digits) == 0:
            v = 0.0                      # no "-0.000"
        return f"{v:+.{self.digits}f}" if self.sign else f"{v:.{self.digits}f}"

    def cell(self) -> str:
        attrs = ""
        if self.path:
            attrs = (f' data-path="{html.escape(self.path)}" data-scale="{self.scale!r}" '
                     f'data-k="{self.k!r}" data-op="{self.op}"')
        return f"<td{attrs}>{html.escape(self.text())}</td>"


@dataclass(frozen=True)
class Verdict:
    """A verdict cell: ``text`` computed by the report from the numbers in its row; ``ok`` True
    (green), False (red) or None (neutral). ``data-verdict`` carries ``ok`` for a reader or a test."""

    text: str
    ok: bool | None = None

    def cell(self) -> str:
        cls = {True: "ok", False: "bad", None: ""}[self.ok]
        flag = {True: "ok", False: "bad", None: "none"}[self.ok]
        c = f' class="{cls}"' if cls else ""
        return f'<td{c} data-verdict="{flag}">{html.escape(self.text)}</td>'


def _cell(c) -> str:
    return c.cell() if isinstance(c, (Num, Verdict)) else f"<td>{html.escape(str(c))}</td>"


@dataclass
class Section:
    """One report section. ``blocks`` are already-escaped HTML fragments built by the helpers below;
    ``key`` names the section in the page: the id of its heading (``<h2 id="key">``, a link target
    ``report.html#key``)."""

    title: str
    blocks: list[str] = field(default_factory=list)
    key: str = ""

    def paragraph(self, text: str, *, cls: str | None = None) -> "Section":
        c = f' class="{cls}"' if cls else ""
        self.blocks.append(f"<p{c}>{html.escape(text)}</p>")
        return self

    def items(self, texts, *, cls: str | None = None) -> "Section":
        """A bulleted list of plain-text items."""
        c = f' class="{cls}"' if cls else ""
        self.blocks.append(f"<ul{c}>" + "".join(f"<li>{html.escape(str(t))}</li>" for t in texts) + "</ul>")
        return self

    def table(self, header, rows, *, caption: str | None = None, name: str | None = None) -> "Section":
        """Add a table; ``rows`` is an iterable of sequences of cells (:class:`Num`, :class:`Verdict`,
        or anything whose str() is escaped). ``name``: a ``data-table`` attribute naming the table
        (for a reader's inspector and the tests)."""
        head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
        body = "".join("<tr>" + "".join(_cell(c) for c in r) + "</tr>" for r in rows)
        cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
        attr = f' data-table="{html.escape(name)}"' if name else ""
        self.blocks.append(f"<table{attr}>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
        return self

    def figure(self, fig, *, caption: str = "") -> "Section":
        """Embed a matplotlib figure as a PNG data URI (the figure is closed afterwards)."""
        import matplotlib.pyplot as plt

        buf = io.BytesIO()
        try:
            fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
        finally:
            plt.close(fig)
        data = base64.b64encode(buf.getvalue()).decode("ascii")
        self.blocks.append(f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}"/>'
                           f"<figcaption>{html.escape(caption)}</figcaption></figure>")
        return self

    def raw(self, fragment: str) -> "Section":
        """Append an HTML fragment made by a trusted library (e.g. plotly's ``to_html``)."""
        self.blocks.append(fragment)
        return self


_CSS = """body{font-family:sans-serif;max-width:64em;margin:2em auto;line-height:1.4;padding:0 1em}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:.2em .6em;text-align:right}
th{background:#eee}caption{caption-side:top;font-weight:bold;text-align:left}img{max-width:100%}
.ok{color:#070}.bad{color:#a00}.warn{color:#a60}.meta td,.meta th{text-align:left}
figcaption{font-size:90%;color:#333}td[data-verdict]{text-align:left}"""


def render(title: str, sections: list[Section], *, subtitle: str | None = None) -> str:
    """The whole report as one HTML string (self-contained: figures are data URIs)."""
    sub = f"<p>{html.escape(subtitle)}</p>" if subtitle else ""
    parts = [f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<link rel='icon' href='data:,'>"
             f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>{sub}"]
    for s in sections:
        key = f' id="{html.escape(s.key)}"' if s.key else ""
        parts.append(f"<section><h2{key}>{html.escape(s.title)}</h2>{''.join(s.blocks)}</section>")
    parts.append("</body></html>")
    return "\n".join(parts)
