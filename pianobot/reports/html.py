"""Self-contained HTML pages: figures as embedded base64 PNG, tables from DataFrames, no network.

Generic helpers shared by every report (run report, discovery report): nothing here knows about
keystrokes. A page is a list of sections; each section is a heading, optional text, figures and
tables. The output has no external links, scripts, stylesheets or fonts, so it opens offline and
can be mailed as one file.
"""

from __future__ import annotations

import base64
import html
import io
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # no display: reports are built on servers and in CI

import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from pianobot.output import write_output  # noqa: E402

_STYLE = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto;
       max-width: 1000px; padding: 0 1em; color: #222; line-height: 1.45; counter-reset: figure; }
h1 { margin-bottom: .1em; }
p.lead { color: #444; margin-top: .2em; }
nav { font-size: .9em; margin: 1em 0 2em; padding: .5em 1em; background: #f6f6f6; }
nav a { margin-right: 1.2em; color: #234; }
h2 { margin-top: 2em; border-bottom: 1px solid #aaa; }
table.data { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
table.data caption { text-align: left; font-weight: bold; padding-bottom: .3em; }
table.data th, table.data td { border: 1px solid #ccc; padding: .25em .6em; text-align: right; }
table.data th { background: #eee; }
table.data td.text { text-align: left; overflow-wrap: anywhere; min-width: 6em; }
div.table { max-width: 100%; overflow-x: auto; }
figure { margin: 1.5em 0; counter-increment: figure; }
figure img { max-width: 100%; height: auto; }
figcaption { font-size: 0.9em; color: #333; max-width: 48em; }
figcaption::before { content: "Figure " counter(figure) ". "; font-weight: bold; }
figcaption .shows { display: block; color: #555; margin-top: .2em; }
p.note { color: #555; font-style: italic; }
p.warning { color: #8a4b00; }
"""


def figure_to_data_uri(fig: Figure, *, dpi: int = 100) -> str:
    """Render a matplotlib figure to a `data:image/png;base64,...` URI and close it."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    encoded = base64.b64encode(buffer.getvalue()).decode("ascii")
    return f"data:image/png;base64,{encoded}"


def figure_html(fig: Figure, caption: str = "", *, shows: str = "", dpi: int = 100) -> str:
    """A numbered `<figure>` with the figure embedded as a PNG.

    Args:
        caption: what the figure is ("On-velocity against arm speed, per vacuum level").
        shows: one sentence on what it shows and how to read it, printed under the caption.
    """
    uri = figure_to_data_uri(fig, dpi=dpi)
    alt = html.escape(caption or "figure", quote=True)
    what = f'<span class="shows">What this shows: {html.escape(shows)}</span>' if shows else ""
    cap = f"<figcaption>{html.escape(caption)}{what}</figcaption>" if caption or shows else ""
    return f'<figure><img src="{uri}" alt="{alt}">{cap}</figure>'


def _cell(value: Any, float_format: str) -> tuple[str, bool]:
    """Format one cell; returns (text, is_text) so text columns can be left-aligned."""
    if value is None:
        return "", False
    if isinstance(value, float):
        if value != value:  # NaN
            return "–", False
        return format(value, float_format), False
    if hasattr(value, "item") and callable(value.item):  # numpy scalar
        return _cell(value.item(), float_format)
    if isinstance(value, bool | int):
        return str(value), False
    return html.escape(str(value)), True


def table_html(
    frame: pd.DataFrame,
    *,
    caption: str = "",
    float_format: str = ".4g",
    index: bool = False,
    table_id: str | None = None,
) -> str:
    """A DataFrame as a plain HTML table (class `data`); NaN shown as an en dash."""
    columns = [str(c) for c in frame.columns]
    head_cells = ([html.escape(str(frame.index.name or ""))] if index else []) + [
        html.escape(c) for c in columns
    ]
    rows = []
    for label, row in frame.iterrows():
        cells = []
        if index:
            cells.append(f'<td class="text">{html.escape(str(label))}</td>')
        for value in row.tolist():
            text, is_text = _cell(value, float_format)
            cells.append(f'<td class="text">{text}</td>' if is_text else f"<td>{text}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    ident = f' id="{html.escape(table_id, quote=True)}"' if table_id else ""
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    head = "<tr>" + "".join(f"<th>{c}</th>" for c in head_cells) + "</tr>"
    # The wrapper scrolls a table too wide for the page on its own, never the whole page.
    return (
        f'<div class="table"><table class="data"{ident}>{cap}<thead>{head}</thead>'
        f"<tbody>{''.join(rows)}</tbody></table></div>"
    )


def mapping_table_html(items: Iterable[tuple[str, Any]], *, caption: str = "") -> str:
    """A two-column key/value table (provenance, settings)."""
    frame = pd.DataFrame([(k, "" if v is None else str(v)) for k, v in items], columns=["key", "value"])
    return table_html(frame, caption=caption)


def paragraph(text: str, *, note: bool = False, warning: bool = False) -> str:
    """Escaped paragraph; `note=True` renders it as a muted remark, `warning=True` stands out."""
    cls = ' class="note"' if note else ' class="warning"' if warning else ""
    return f"<p{cls}>{html.escape(text)}</p>"


@dataclass
class Section:
    """One titled part of a page: its body is a list of HTML fragments made by the helpers above."""

    title: str
    parts: list[str] = field(default_factory=list)

    def add(self, fragment: str) -> Section:
        """Append a fragment (figure, table, paragraph) and return self for chaining."""
        self.parts.append(fragment)
        return self

    def render(self) -> str:
        anchor = html.escape(_slug(self.title), quote=True)
        return f'<section id="{anchor}"><h2>{html.escape(self.title)}</h2>{"".join(self.parts)}</section>'


def _slug(title: str) -> str:
    """`Keystroke stages: measured and model` → `keystroke-stages-measured-and-model`."""
    return re.sub(r"[^0-9a-z]+", "-", title.lower()).strip("-") or "section"


def page_html(title: str, sections: Sequence[Section], *, subtitle: str = "") -> str:
    """Assemble a complete, self-contained HTML document (inline CSS only, no external resources).

    The title and a one-line subtitle head the page, then links to each section.
    """
    sub = f'<p class="lead">{html.escape(subtitle)}</p>' if subtitle else ""
    links = "".join(f'<a href="#{html.escape(_slug(s.title), quote=True)}">{html.escape(s.title)}</a>'
                    for s in sections)
    nav = f"<nav>{links}</nav>" if len(sections) > 1 else ""
    body = "".join(s.render() for s in sections)
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
        f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head>"
        f"<body><h1>{html.escape(title)}</h1>{sub}{nav}{body}</body></html>\n"
    )


def write_page(path: Path, title: str, sections: Sequence[Section], *, subtitle: str = "") -> Path:
    """Write the page atomically (temp file + rename) so a half-written report never exists."""
    text = page_html(title, sections, subtitle=subtitle)
    return write_output(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
