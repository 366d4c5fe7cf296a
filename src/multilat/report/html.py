"""A small, escaped HTML report: sections of paragraphs, tables and embedded PNG figures."""

from __future__ import annotations

import base64
import html
import io
from dataclasses import dataclass, field


@dataclass
class Section:
    """One report section. ``blocks`` are already-escaped HTML fragments built by the helpers below."""

    title: str
    blocks: list[str] = field(default_factory=list)

    def paragraph(self, text: str) -> "Section":
        self.blocks.append(f"<p>{html.escape(text)}</p>")
        return self

    def table(self, header, rows, *, caption: str | None = None) -> "Section":
        """Add a table; ``rows`` is an iterable of sequences of cells (str() of each is escaped)."""
        head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                       for r in rows)
        cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
        self.blocks.append(f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
        return self

    def figure(self, fig, *, caption: str = "") -> "Section":
        """Embed a matplotlib figure as a PNG (the figure is closed afterwards)."""
        import matplotlib.pyplot as plt

        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        data = base64.b64encode(buf.getvalue()).decode("ascii")
        self.blocks.append(f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}"/>'
                           f"<figcaption>{html.escape(caption)}</figcaption></figure>")
        return self


_CSS = """body{font-family:sans-serif;max-width:60em;margin:2em auto;line-height:1.4}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:.2em .6em;text-align:right}
th{background:#eee}caption{caption-side:top;font-weight:bold;text-align:left}img{max-width:100%}
.ok{color:#070}.bad{color:#a00}"""


def render(title: str, sections: list[Section]) -> str:
    """The whole report as one HTML string."""
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>"]
    for s in sections:
        parts.append(f"<section><h2>{html.escape(s.title)}</h2>{''.join(s.blocks)}</section>")
    parts.append("</body></html>")
    return "\n".join(parts)
