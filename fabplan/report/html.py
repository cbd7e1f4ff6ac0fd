"""Self-contained HTML pages: page, sections, tables, figures, counts and values.

Reports are single HTML files that open offline: pictures are PNG images embedded as
``data:`` URIs, styles are inline, nothing is fetched. The helpers are generic so that
every report-writing module (molds, strips, facade studies) builds its page the same way::

    from fabplan.report import figures, html
    page = html.html_page("Title", [
        html.html_section("Summary", html.html_table(["quantity", "value"], rows)),
        html.html_figure(figures.figure_to_data_uri(fig), "caption"),
    ])
"""

from __future__ import annotations

import html
import math
import re
from typing import Iterable, NamedTuple, Sequence

import numpy as np

__all__ = [
    "html_page",
    "html_section",
    "html_paragraph",
    "html_table",
    "html_figure",
    "html_details",
    "format_value",
    "counted",
    "panel_areas",
    "html_links",
    "format_range",
    "section_id",
    "LINKS_NOTE",
    "html_figure_grid",
    "Cell",
]

#: Said wherever a report links to its files.
LINKS_NOTE = ("Links are relative to this report's folder: move or share the folder as a "
              "whole and they keep working.")

_STYLE = """
body { font-family: system-ui, -apple-system, 'Segoe UI', Helvetica, Arial, sans-serif;
       margin: 2em auto; max-width: 1200px; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.7em; margin-bottom: 0.2em; }
h2 { font-size: 1.3em; margin-top: 1.8em; border-bottom: 1px solid #ccc; padding-bottom: 0.2em; }
p.subtitle { color: #555; margin-top: 0; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
caption { text-align: left; font-weight: 600; padding: 0.3em 0; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; }
th { background: #f0f0f0; position: sticky; top: 0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
tr.bad td { background: #fde2e2; }
figure { margin: 1.2em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { color: #444; font-size: 0.92em; margin-top: 0.3em; }
details summary { cursor: pointer; font-weight: 600; margin: 0.6em 0; }
.note { background: #f6f8fa; border-left: 4px solid #7a9cc6; padding: 0.6em 1em; }
.fail { background: #fde2e2; border-left: 4px solid #c0392b; padding: 0.6em 1em; }
.how { background: #fbf8ec; border-left: 4px solid #c9a227; padding: 0.4em 1em; font-size: 0.92em; }
.figs { display: grid; grid-template-columns: repeat(auto-fit, minmax(440px, 1fr)); gap: 0 1.2em; }
nav.toc { background: #f6f8fa; padding: 0.5em 1.2em; display: inline-block; }
nav.toc ol { margin: 0.2em 0; padding-left: 1.4em; }
figure img { max-height: 80vh; }
table.sortable th { cursor: pointer; user-select: none; }
table.sortable th[aria-sort="ascending"]::after { content: " \\25B2"; font-size: 0.7em; }
table.sortable th[aria-sort="descending"]::after { content: " \\25BC"; font-size: 0.7em; }
@media print { h2 { page-break-before: auto; } th { position: static; } }
"""

# Click a header of a sortable table to sort its rows by that column (again: the other
# way). Numbers sort by the value in data-v (as written, not as rounded on the page);
# empty cells go last either way.
_SORT_SCRIPT = """<script>
document.querySelectorAll("table.sortable").forEach(function (table) {
  table.querySelectorAll("thead th").forEach(function (th, col) {
    th.title = "sort by this column";
    th.addEventListener("click", function () {
      var up = th.getAttribute("aria-sort") !== "ascending";
      table.querySelectorAll("thead th").forEach(function (h) { h.removeAttribute("aria-sort"); });
      th.setAttribute("aria-sort", up ? "ascending" : "descending");
      var body = table.tBodies[0], rows = Array.prototype.slice.call(body.rows);
      function key(row) {
        var td = row.cells[col]; if (!td) return null;
        if (td.hasAttribute("data-v")) return parseFloat(td.getAttribute("data-v"));
        var t = td.textContent.trim(); return (t === "" || t === "\u2013") ? null : t;
      }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b);
        if (x === null || y === null) return (x === null) - (y === null);
        var c = (typeof x === "number" && typeof y === "number") ? x - y
                : String(x).localeCompare(String(y), undefined, {numeric: true});
        return up ? c : -c;
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});
</script>"""


def format_value(value, digits: int = 4) -> str:
    """Text of a table cell: numbers with `digits` significant digits, None as an en dash.

    Examples
    --------
    >>> format_value(3.14159), format_value(12), format_value(None), format_value(True)
    ('3.142', '12', '–', 'yes')
    """
    if value is None:
        return "–"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value):
            return "–"
        return f"{value:.{digits}g}"
    return str(value)


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """A count with its noun in the right number.

    Examples
    --------
    >>> counted(1, "mold"), counted(0, "mold"), counted(3, "sheet"), counted(2, "box", "boxes")
    ('1 mold', '0 molds', '3 sheets', '2 boxes')
    """
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def panel_areas(count: float) -> str:
    """An area in full panels, in words.

    Examples
    --------
    >>> panel_areas(0.0412), panel_areas(2.46), panel_areas(54.2)
    ('0.04 panel', '2.5 panels', '54 panels')
    """
    text = f"{count:.2f}" if count < 1 else f"{count:.1f}" if count < 10 else f"{count:.0f}"
    return f"{text} panel{'' if count < 1 else 's'}"


def format_range(low, high, unit: str = "", digits: int = 4) -> str:
    """``low .. high unit``, or a single value when both read the same.

    Examples
    --------
    >>> format_range(44.0001, 44.0002, "deg"), format_range(2.06, 4.995, "m"), format_range(1, 2)
    ('44 deg', '2.06 .. 4.995 m', '1 .. 2')
    """
    lo, hi = format_value(low, digits), format_value(high, digits)
    text = lo if lo == hi else f"{lo} .. {hi}"
    return f"{text} {unit}" if unit and text != "–" else text


_NUMBER = re.compile(r"^[-+]?(\d+(\.\d*)?|\.\d+)(e[-+]?\d+)?$", re.IGNORECASE)


class Cell(NamedTuple):
    """A table cell shown as `text` and sorted by `value` (a number rounded for the page
    still sorts by its full value)."""

    text: str
    value: float


def _empty(value) -> bool:
    return value is None or (isinstance(value, str) and value.strip() in ("", "–"))


def html_table(columns: Sequence[str], rows: Iterable[Sequence], *, caption: str | None = None,
               digits: int = 4, bad_rows: Iterable[int] = (), hide_empty: bool = False,
               sortable: bool = False) -> str:
    """An HTML table; numbers are right-aligned and formatted by `format_value`.

    Parameters
    ----------
    columns : header texts.
    rows : rows of cell values (numbers, strings, None).
    caption : optional caption above the table.
    bad_rows : indices of rows to highlight (failures).
    hide_empty : leave out the columns that are empty in every row.
    sortable : a click on a header sorts the rows by that column (`html_page` adds the
        script); numeric cells carry their full value in ``data-v``.

    Examples
    --------
    >>> table = html_table(["a", "b"], [[1, None]])
    >>> table[table.index("<tbody>"):]
    '<tbody><tr><td class="num">1</td><td>–</td></tr></tbody></table>'
    """
    bad = set(bad_rows)
    rows = [list(r) for r in rows]
    if hide_empty and rows:
        keep = [j for j in range(len(columns)) if not all(_empty(r[j]) for r in rows)]
        columns = [columns[j] for j in keep]
        rows = [[r[j] for j in keep] for r in rows]
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
    body = []
    for i, row in enumerate(rows):
        cells = []
        for value in row:
            if isinstance(value, Cell):
                full = f' data-v="{float(value.value)!r}"' if sortable else ""
                cells.append(f'<td class="num"{full}>{html.escape(value.text)}</td>')
                continue
            numeric = (isinstance(value, (int, float, np.integer, np.floating))
                       and not isinstance(value, (bool, np.bool_))
                       or isinstance(value, str) and _NUMBER.match(value) is not None)
            cls = ' class="num"' if numeric else ""
            if sortable and numeric:
                number = _NUMBER.match(value) if isinstance(value, str) else None
                exact = float(number.group(0)) if number is not None else float(value)
                cls += f' data-v="{exact!r}"'
            cells.append(f"<td{cls}>{html.escape(format_value(value, digits))}</td>")
        tr = '<tr class="bad">' if i in bad else "<tr>"
        body.append(tr + "".join(cells) + "</tr>")
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    table = '<table class="sortable">' if sortable else "<table>"
    return f"{table}{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def html_paragraph(text: str, *, cls: str | None = None) -> str:
    r"""A paragraph of escaped text (``cls``: ``"note"`` or ``"fail"`` for a framed box);
    its lines (``\n``) are kept apart.

    Examples
    --------
    >>> html_paragraph("a < b\nc")
    '<p>a &lt; b<br>c</p>'
    """
    attr = f' class="{cls}"' if cls else ""
    lines = text.split("\n")
    return f"<p{attr}>{'<br>'.join(html.escape(line) for line in lines)}</p>"


def html_links(label: str, links: Sequence[tuple[str, str]]) -> str:
    """A paragraph of links: `label` then ``(text, href)`` pairs (hrefs relative to the
    page, so that a report folder can be moved or shared as a whole).

    Examples
    --------
    >>> html_links("Files", [("net.obj", "candidates/a b/net.obj")])
    '<p>Files: <a href="candidates/a%20b/net.obj">net.obj</a></p>'
    """
    from urllib.parse import quote

    items = ", ".join(f'<a href="{html.escape(quote(href))}">{html.escape(text)}</a>'
                      for text, href in links)
    return f"<p>{html.escape(label)}: {items}</p>"


def html_figure(uri: str, caption: str, *, alt: str | None = None, how: str | None = None) -> str:
    """An embedded picture with its caption and, when given, a short "how to read this"."""
    box = f'<div class="how"><b>How to read this:</b> {html.escape(how)}</div>' if how else ""
    return (f'<figure><img src="{uri}" alt="{html.escape(alt or caption)}">'
            f"<figcaption>{html.escape(caption)}</figcaption>{box}</figure>")


def html_figure_grid(*figures: str) -> str:
    """Figures side by side (two in a row on a wide page, one on a narrow one)."""
    return f'<div class="figs">{"".join(figures)}</div>'


def html_details(summary: str, *parts: str) -> str:
    """A collapsible block (long tables)."""
    return f"<details><summary>{html.escape(summary)}</summary>{''.join(parts)}</details>"


def section_id(title: str) -> str:
    """The anchor of a section: its title in lower case, words joined by hyphens.

    Examples
    --------
    >>> section_id("2. Isogonal 60 deg: ok?")
    '2-isogonal-60-deg-ok'
    """
    return "-".join(re.findall(r"[a-z0-9]+", title.lower())) or "section"


def html_section(title: str, *parts: str, anchor: str | None = None) -> str:
    """A titled section of already built HTML parts; its anchor (`section_id` of the title
    unless given) is what the page's table of contents links to."""
    return (f'<section id="{html.escape(anchor or section_id(title))}"><h2>{html.escape(title)}'
            f"</h2>{''.join(parts)}</section>")


_SECTION = re.compile(r'<section id="([^"]+)"><h2>(.*?)</h2>')


def html_page(title: str, parts: Iterable[str], *, subtitle: str | None = None,
              toc: bool = True, scripts: str = "") -> str:
    """A complete, self-contained HTML document.

    toc : put a table of contents of the sections (`html_section`) under the title.
    scripts : HTML put at the end of the body (`fabplan.report.viewer.viewer_assets`).
    """
    sub = f'<p class="subtitle">{html.escape(subtitle)}</p>' if subtitle else ""
    body = "".join(parts)
    nav = ""
    if toc:
        entries = _SECTION.findall(body)
        if len(entries) > 1:
            nav = ('<nav class="toc"><b>Contents</b><ol>'
                   + "".join(f'<li><a href="#{a}">{t}</a></li>' for a, t in entries)
                   + "</ol></nav>")
    if 'class="sortable"' in body:
        scripts = _SORT_SCRIPT + scripts
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head>"
            f"<body><h1>{html.escape(title)}</h1>{sub}{nav}{body}{scripts}</body></html>\n")
