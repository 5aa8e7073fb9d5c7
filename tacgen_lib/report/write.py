"""Writing report items: figures as PNG and tables as standalone HTML, atomic and deterministic.

Report items are written like edges (temp file + rename: an interrupted job leaves no half
page), and their bytes depend only on their content: matplotlib's `Software` metadata (which
carries its version) is left out, and no timestamp is written.
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterable

import matplotlib.pyplot as plt
import pandas as pd

from tacgen_lib.io.edges import atomic_write_bytes
from tacgen_lib.report.tables import to_html

__all__ = ["FIGURE_DPI", "write_figure", "write_table"]

FIGURE_DPI = 110


def write_figure(fig: plt.Figure, path: str | os.PathLike[str], *, dpi: int = FIGURE_DPI) -> None:
    """Save `fig` as PNG at `path` atomically, with no varying metadata, then close it."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def write_table(
    table: pd.DataFrame,
    path: str | os.PathLike[str],
    *,
    title: str,
    mono: Iterable[str] = ("sha256", "edge"),
) -> None:
    """Write `table` as a standalone HTML page (`tables.to_html`) at `path`, atomically."""
    atomic_write_bytes(path, to_html(table, title=title, mono=mono).encode())
