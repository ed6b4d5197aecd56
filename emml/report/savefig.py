"""Figures written byte for byte the same from the same data: `make reports` on unchanged results changes no
committed file. Matplotlib stamps the date (PDF, SVG) and its version (PNG 'Software') into a figure unless told not
to, and salts SVG ids at random. And one style for every figure (emml/report/emml.mplstyle: TrueType fonts in PDFs,
the sizes, the grid), applied when this module is imported: every figure module saves through it."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.style

from emml.runs.atomic import replacing
from emml.runs.diskspace import RERUN

METADATA = {
    ".png": {"Software": None},
    ".pdf": {"CreationDate": None, "ModDate": None, "Producer": None, "Creator": None},
    ".svg": {"Date": None, "Creator": None},
}
"""What each format would otherwise stamp: the date, matplotlib's version."""
SVG_HASHSALT = "emml"
"""A fixed salt for the ids of SVG elements (random by default)."""
STYLE = Path(__file__).with_name("emml.mplstyle")
"""The style sheet of every figure under reports/."""


def use_style() -> None:
    """Apply STYLE to matplotlib's rcParams (idempotent)."""
    matplotlib.style.use(STYLE)


use_style()


VECTOR = (".pdf", ".svg", ".ps", ".eps")
"""Formats laid out in points: matplotlib draws them at 72 dpi whatever ``dpi`` says."""
SETTLE_PASSES = 8
"""At most this many layout passes before a file is written (`settle`)."""
SETTLE_TOLERANCE = 1e-3
"""Axes that move less than this (a fraction of the figure: under a pixel at 120 dpi) between two passes have
settled."""


def file_dpi(path: str | Path, dpi: float | None = None) -> float:
    """The dpi ``path``'s format is drawn at: 72 for a vector format, else ``dpi`` or savefig.dpi (the PNG's)."""
    if Path(path).suffix.lower() in VECTOR:
        return 72.0
    return float(dpi or matplotlib.rcParams["savefig.dpi"])


def settle(fig, dpi: float) -> None:
    """Lay ``fig`` out at ``dpi`` until its axes stop moving. A constrained layout runs two passes from where the
    axes stand, and a legend anchored to an axes moves as that axes shrinks for it: drawn once from the figure's
    first positions, a legend wider than its axes can still leave the canvas (the first file written, a PNG at 120
    dpi, cut it; the PDF written after it started from the PNG's layout and was whole). Settled first, every file
    of the figure is drawn from a layout that holds at its own dpi, whichever is written first."""
    engine = fig.get_layout_engine()
    if engine is None or not fig.axes:
        return
    before = fig.dpi
    fig.dpi = dpi
    try:
        for _ in range(SETTLE_PASSES):
            start = [ax.get_position().bounds for ax in fig.axes]
            fig.draw_without_rendering()
            end = [ax.get_position().bounds for ax in fig.axes]
            moved = max(abs(a - b) for s, e in zip(start, end) for a, b in zip(s, e))
            if moved < SETTLE_TOLERANCE:
                break
    finally:
        fig.dpi = before


def save(fig, path: str | Path, **kwargs) -> Path:
    """``fig.savefig(path, **kwargs)`` with no date or version stamped into the file, whole or not at all (a temp
    file, then a rename: `emml.runs.atomic.replacing`; its format named, the temp file's suffix being .tmp), its
    layout settled at the file's dpi first (`settle`)."""
    path = Path(path)
    settle(fig, file_dpi(path, kwargs.get("dpi")))
    with replacing(path, then=RERUN) as tmp, matplotlib.rc_context({"svg.hashsalt": SVG_HASHSALT}):
        fig.savefig(tmp, format=path.suffix[1:].lower(), metadata=METADATA.get(path.suffix.lower()), **kwargs)
    return path


COLUMN_INCHES = 3.3
"""A figure one column of a two-column paper wide: made at the width it prints at, its 7-8 pt text prints at 7-8 pt."""
PAGE_INCHES = 7.0
"""A figure the text width of a two-column page wide (`figure*`)."""
PAGE_HEIGHT_INCHES = 9.0
"""The tallest figure a page holds with its caption (a letter or A4 page's text is ~9 in tall): every figure is at
most `PAGE_INCHES` × `PAGE_HEIGHT_INCHES`, its notes in a caption beside it (`caption_path`), not inside it."""


def caption_path(figure: str | Path) -> Path:
    """Where a figure's caption is written beside it: its PNG's and PDF's stem, ``.txt`` (markdown text the page
    that embeds the figure prints under it)."""
    return Path(figure).with_suffix(".txt")


def frames_axis(ax) -> None:
    """x in millions of frames ('M frames', ticks 0, 0.5, 1, ...), not matplotlib's '1e6' offset."""
    from matplotlib.ticker import FuncFormatter

    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1e6:g}"))
    ax.set_xlabel("M frames")


def wrap(text: str, inches: float, points: float) -> str:
    """``text`` wrapped to lines that fit ``inches`` at ``points`` (a character ~0.6 em wide: DejaVu Sans)."""
    import textwrap

    return "\n".join(textwrap.wrap(text, max(10, int(inches * 72 / (0.6 * points))))) or text


def outside(fig, dpi: float | None = None) -> list[str]:
    """The texts of ``fig`` drawn (titles, labels, tick labels, legends, annotations) whose extent leaves the
    canvas: what the file cuts off. Drawn at ``dpi`` (default: the dpi files are saved at; text does not scale
    exactly with it). A tick label outside its axis' view is not drawn, and not counted."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if not hasattr(fig.canvas, "get_renderer"):  # a closed figure: drawn again as it is saved
        FigureCanvasAgg(fig)
    fig.set_dpi(dpi or matplotlib.rcParams["savefig.dpi"])
    fig.canvas.draw()
    return cut(fig, fig.canvas.get_renderer())


def cut(fig, renderer) -> list[str]:
    """`outside` of ``fig`` as ``renderer`` has just drawn it, at the dpi it drew at (no new draw: on a
    ``draw_event`` of ``savefig``, the file's own layout and text sizes)."""
    from matplotlib.text import Text

    hidden = set()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                if not lo - 1e-9 * max(1, abs(hi)) <= tick.get_loc() <= hi + 1e-9 * max(1, abs(hi)):
                    hidden |= {id(tick.label1), id(tick.label2)}
    box, out = fig.bbox, []
    for text in fig.findobj(Text):
        if id(text) in hidden or not text.get_visible() or not text.get_text().strip():
            continue
        e = text.get_window_extent(renderer)
        if e.x0 < box.x0 - 0.5 or e.y0 < box.y0 - 0.5 or e.x1 > box.x1 + 0.5 or e.y1 > box.y1 + 0.5:
            out.append(text.get_text())
    return out
