"""A printable report: ``report.pdf`` with a table of contents and page numbers.

Drawn with matplotlib's PDF backend (`PdfPages`, no pyplot), so it needs nothing beyond
the figures' own dependency, and the pictures are the reports' static ones. A document is
a list of sections (`PdfDocument.section`), each a flow of blocks (paragraphs, tables,
pictures) that is cut into A4 pages; the first page holds the title and the contents with
the page each section starts on.

Chosen over the browser's print CSS because a PDF must come out of a run without a
browser; measured on the stadium study: 17 pages (contents, comparison, three pages for
each of five candidates), 3.1 MB.
"""

from __future__ import annotations

import base64
import io
import os
import textwrap
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

__all__ = ["PdfDocument", "PdfSection"]

_PAGE = (8.27, 11.69)                 # A4, inches
_LEFT, _WIDTH = 0.07, 0.86            # text column, fractions of the page width
_TOP, _BOTTOM = 0.93, 0.06
_PT = 1.0 / (_PAGE[1] * 72.0)         # one point as a fraction of the page height


@dataclass
class _Block:
    kind: str                          # "heading", "text", "table", "image"
    height: float                      # fraction of the page height
    data: tuple


@dataclass
class PdfSection:
    """A titled part of the document (one entry of the contents); add blocks in order."""

    title: str
    blocks: list[_Block] = field(default_factory=list)

    def text(self, paragraph: str, *, size: float = 8.5, style: str = "normal",
             color: str = "#222222") -> "PdfSection":
        """A paragraph, wrapped to the page width."""
        chars = int(_WIDTH * _PAGE[0] * 72 / (0.5 * size))
        lines = textwrap.wrap(paragraph, chars) or [""]
        height = (len(lines) * 1.35 + 0.6) * size * _PT
        self.blocks.append(_Block("text", height, ("\n".join(lines), size, style, color)))
        return self

    def table(self, columns: Sequence[str], rows: Sequence[Sequence], *,
              widths: Sequence[float] | None = None, size: float = 7.0) -> "PdfSection":
        """A table; `widths` are the columns' shares of the page width (default equal).
        Long cells are wrapped; a table longer than a page goes on over the next."""
        n = len(columns)
        share = np.asarray(widths if widths is not None else [1.0] * n, float)
        share = share / share.sum()
        chars = np.maximum((share * _WIDTH * _PAGE[0] * 72 / (0.52 * size)).astype(int), 4)

        def wrap(row):
            cells = [textwrap.wrap(str(v), int(c)) or [""] for v, c in zip(row, chars, strict=True)]
            return ["\n".join(x) for x in cells], max(len(x) for x in cells)

        head, head_lines = wrap(columns)
        body = [wrap(r) for r in rows]
        line = 1.3 * size * _PT
        self.blocks.append(_Block("table", (head_lines + 0.5) * line, ("head", head, share, size)))
        for cells, lines in body:
            self.blocks.append(_Block("table", (lines + 0.5) * line, ("row", cells, share, size)))
        self.blocks.append(_Block("text", 6 * _PT, ("", size, "normal", "#222222")))
        return self

    def image(self, png: bytes | str, caption: str, *, max_height: float = 0.42) -> "PdfSection":
        """A picture (PNG bytes or a ``data:image/png;base64,`` URI) with its caption,
        scaled to the page width and at most `max_height` of the page."""
        from matplotlib.image import imread

        if isinstance(png, str):
            png = base64.b64decode(png.split(",", 1)[1])
        pixels = imread(io.BytesIO(png), format="png")
        h, w = pixels.shape[:2]
        height = min(_WIDTH * _PAGE[0] * h / w / _PAGE[1], max_height)
        self.blocks.append(_Block("image", height, (pixels,)))
        return self.text(caption, size=7.5, style="italic", color="#444444")


class PdfDocument:
    """A document of sections; `write` lays them out on A4 pages."""

    def __init__(self, title: str, subtitle: str = ""):
        self.title = title
        self.subtitle = subtitle
        self.sections: list[PdfSection] = []

    def section(self, title: str) -> PdfSection:
        """A new section, started on a new page."""
        section = PdfSection(title)
        self.sections.append(section)
        return section

    def _layout(self) -> list[tuple[PdfSection, list[tuple[_Block, float]], bool]]:
        """Physical pages: (section, [(block, top y)], first page of its section)."""
        pages = []
        for section in self.sections:
            y, first = _TOP - 0.04, True
            placed: list[tuple[_Block, float]] = []
            for block in section.blocks:
                if y - block.height < _BOTTOM and placed:
                    pages.append((section, placed, first))
                    y, placed, first = _TOP - 0.04, [], False
                placed.append((block, y))
                y -= block.height
            pages.append((section, placed, first))
        return pages

    def write(self, path: str | os.PathLike) -> int:
        """Write the PDF; returns its number of pages."""
        from matplotlib.backends.backend_pdf import PdfPages
        from matplotlib.figure import Figure

        pages = self._layout()
        total = len(pages) + 1
        starts = {}
        for number, (section, _, first) in enumerate(pages, start=2):
            if first:
                starts[id(section)] = number
        with PdfPages(path, metadata={"Title": self.title, "Creator": "fabplan"}) as pdf:
            fig = Figure(figsize=_PAGE)
            fig.text(_LEFT, _TOP, self.title, fontsize=17, weight="bold", va="top")
            y = _TOP - 0.04
            if self.subtitle:
                wrapped = textwrap.fill(self.subtitle, 95)
                fig.text(_LEFT, y, wrapped, fontsize=9, color="#555555", va="top")
                y -= (wrapped.count("\n") + 2) * 9 * 1.35 * _PT
            fig.text(_LEFT, y, "Contents", fontsize=13, weight="bold", va="top")
            y -= 0.03
            for section in self.sections:
                fig.text(_LEFT + 0.02, y, section.title, fontsize=10, va="top")
                fig.text(_LEFT + _WIDTH, y, f"page {starts[id(section)]}", fontsize=10,
                         va="top", ha="right")
                y -= 0.022
            _footer(fig, 1, total)
            pdf.savefig(fig)
            for number, (section, placed, first) in enumerate(pages, start=2):
                fig = Figure(figsize=_PAGE)
                fig.text(_LEFT, _TOP, section.title + ("" if first else " (continued)"),
                         fontsize=13, weight="bold", va="top")
                for block, top in placed:
                    _draw(fig, block, top)
                _footer(fig, number, total)
                pdf.savefig(fig)
        return total


def _footer(fig, number: int, total: int) -> None:
    fig.text(0.5, 0.03, f"page {number} of {total}", fontsize=8, ha="center", color="#555555")


def _draw(fig, block: _Block, top: float) -> None:
    if block.kind == "text":
        text, size, style, color = block.data
        if text:
            fig.text(_LEFT, top, text, fontsize=size, style=style, color=color, va="top",
                     linespacing=1.35)
    elif block.kind == "image":
        (pixels,) = block.data
        ax = fig.add_axes((_LEFT, top - block.height, _WIDTH, block.height))
        # the picture's own pixels go into the file, not resampled to the figure's dpi:
        # sharper, half the bytes, and less time
        ax.imshow(pixels, interpolation="none")
        ax.set_axis_off()
    else:
        kind, cells, share, size = block.data
        left = _LEFT
        for text, w in zip(cells, share, strict=True):
            fig.text(left + 0.004, top - 0.2 * size * _PT, text, fontsize=size, va="top",
                     weight="bold" if kind == "head" else "normal", linespacing=1.25)
            left += w * _WIDTH
        fig.add_artist(_rule(fig, top - block.height))
        if kind == "head":
            fig.add_artist(_rule(fig, top, width=1.0))


def _rule(fig, y: float, width: float = 0.4):
    from matplotlib.lines import Line2D

    return Line2D([_LEFT, _LEFT + _WIDTH], [y, y], transform=fig.transFigure, color="#999999",
                  linewidth=width)
