"""Reports: self-contained HTML pages with embedded figures (`html` holds the generic helpers)."""

from pianobot.reports.html import (
    Section,
    figure_html,
    figure_to_data_uri,
    mapping_table_html,
    page_html,
    paragraph,
    table_html,
    write_page,
)

__all__ = [
    "Section",
    "figure_html",
    "figure_to_data_uri",
    "mapping_table_html",
    "page_html",
    "paragraph",
    "table_html",
    "write_page",
]
