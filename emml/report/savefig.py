"""Figures written byte for byte the same from the same data: `make reports` on unchanged results changes no
committed file. Matplotlib stamps the date (PDF, SVG) and its version (PNG 'Software') into a figure unless told not
to, and salts SVG ids at random."""

from __future__ import annotations

from pathlib import Path

import matplotlib

METADATA = {
    ".png": {"Software": None},
    ".pdf": {"CreationDate": None, "ModDate": None, "Producer": None, "Creator": None},
    ".svg": {"Date": None, "Creator": None},
}
"""What each format would otherwise stamp: the date, matplotlib's version."""
SVG_HASHSALT = "emml"
"""A fixed salt for the ids of SVG elements (random by default)."""


def save(fig, path: str | Path, **kwargs) -> Path:
    """``fig.savefig(path, **kwargs)`` with no date or version stamped into the file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with matplotlib.rc_context({"svg.hashsalt": SVG_HASHSALT}):
        fig.savefig(path, metadata=METADATA.get(path.suffix.lower()), **kwargs)
    return path
