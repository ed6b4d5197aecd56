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


def save(fig, path: str | Path, **kwargs) -> Path:
    """``fig.savefig(path, **kwargs)`` with no date or version stamped into the file, whole or not at all (a temp
    file, then a rename: `emml.runs.atomic.replacing`; its format named, the temp file's suffix being .tmp)."""
    path = Path(path)
    with replacing(path, then=RERUN) as tmp, matplotlib.rc_context({"svg.hashsalt": SVG_HASHSALT}):
        fig.savefig(tmp, format=path.suffix[1:].lower(), metadata=METADATA.get(path.suffix.lower()), **kwargs)
    return path
