"""Writing report items: figures as PNG and tables as standalone HTML, atomic and deterministic.

Report items are written like edges (temp file + rename: an interrupted job leaves no half
page), and their bytes depend only on their content: matplotlib's `Software` metadata (which
carries its version) is left out, and no timestamp is written.
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterable
from typing import TYPE_CHECKING

import pandas as pd

from tacgen_lib.io.hashed import atomic_write_bytes
from tacgen_lib.report.tables import to_html

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "FIGURE_DPI",
    "MAX_FIGURE_PX",
    "MIN_FONT_PT",
    "figure_problems",
    "panel_grid",
    "write_figure",
    "write_table",
]

FIGURE_DPI = 110
#: the largest figure Snakemake's viewer shows whole and at full size in a 1600-by-1000 window:
#: its image pane is 1,070–1,180 px wide beside the menu (the menu grows with its labels), and
#: it centres an image vertically,
#: cutting off (unscrollably) whatever is taller than the window
MAX_FIGURE_PX = (1050, 950)
#: the smallest text, in points at FIGURE_DPI: shown at full size, 8 pt at 110 dpi is 12.2 CSS
#: px, i.e. 9 pt on the reader's screen
MIN_FONT_PT = 8.0


def figure_problems(fig: Figure, *, dpi: int = FIGURE_DPI) -> list[str]:
    """Why `fig` would not be readable in the report viewer: too large for it (so shown scaled
    down or cropped), or text smaller than `MIN_FONT_PT`. Empty when it is readable."""
    import matplotlib.text  # a figure's caller has imported matplotlib; a table's need not

    w, h = (float(x) * dpi for x in fig.get_size_inches())
    problems = []
    if w > MAX_FIGURE_PX[0] + 0.5 or h > MAX_FIGURE_PX[1] + 0.5:
        problems.append(
            f"{w:.0f}×{h:.0f} px is larger than the viewer shows whole "
            f"({MAX_FIGURE_PX[0]}×{MAX_FIGURE_PX[1]} px)"
        )
    small = sorted(
        {
            (round(t.get_fontsize(), 1), t.get_text()[:30])
            for t in fig.findobj(matplotlib.text.Text)
            if t.get_visible() and t.get_text().strip() and t.get_fontsize() < MIN_FONT_PT
        }
    )
    if small:
        problems.append(
            f"text below {MIN_FONT_PT:g} pt: "
            + "; ".join(f"{size:g} pt {text!r}" for size, text in small[:5])
        )
    return problems


def write_figure(fig: Figure, path: str | os.PathLike[str], *, dpi: int = FIGURE_DPI) -> None:
    """Save `fig` as PNG at `path` atomically, with no varying metadata, then close it.

    Refuses (ValueError naming the file) a figure the report viewer could not show readably
    (`figure_problems`): nothing is written."""
    import matplotlib.pyplot as plt  # here: the jobs that only write tables skip pyplot

    problems = figure_problems(fig, dpi=dpi)
    if problems:
        plt.close(fig)
        raise ValueError(f"{path}: figure not readable in the report: {'; '.join(problems)}")
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
    missing: str = "not defined for this row",
    notes: Iterable[str] = (),
    lead: Iterable[str] = (),
) -> None:
    """Write `table` as a standalone HTML page (`tables.to_html`) at `path`, atomically."""
    page = to_html(table, title=title, mono=mono, missing=missing, notes=notes, lead=lead)
    atomic_write_bytes(path, page.encode())


def panel_grid(
    n: int,
    panel: tuple[float, float],
    *,
    max_cols: int | None = None,
    min_height: float = 1.8,
    dpi: int = FIGURE_DPI,
) -> tuple[int, int, tuple[float, float]]:
    """(nrows, ncols, figsize) for `n` panels of `panel` inches laid out to fit the viewer
    (`MAX_FIGURE_PX`): as many columns as fit across, then rows; rows shorter than `panel`
    (down to `min_height`) where they would not fit down. ValueError where even that does not
    fit: the caller splits its panels over several figures (one per family or knob)."""
    max_w, max_h = MAX_FIGURE_PX[0] / dpi, MAX_FIGURE_PX[1] / dpi
    fit = max(1, int(max_w // panel[0]))
    ncols = max(1, min(n, fit, max_cols or fit))
    nrows = max(1, -(-n // ncols))
    height = min(panel[1], max_h / nrows)
    if height < min_height:
        raise ValueError(
            f"{n} panels of {panel[0]}×{panel[1]} in do not fit one figure in the viewer; "
            "split them over several figures"
        )
    return nrows, ncols, (min(panel[0] * ncols, max_w), height * nrows)
