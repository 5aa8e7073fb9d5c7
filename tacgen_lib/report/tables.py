"""Tables for the Snakemake report: small, self-contained HTML (no network, no scripts)."""

from __future__ import annotations

import html
import re
from collections.abc import Iterable
from pathlib import Path

import pandas as pd

from tacgen_lib.io import hashed
from tacgen_lib.report import format as fmt

__all__ = [
    "cell_html",
    "constants_to_lead",
    "edge_manifest_table",
    "footnote_column",
    "pretrained_vs_random_view",
    "to_html",
]


def edge_manifest_table(paths: Iterable[str]) -> pd.DataFrame:
    """One row per edge: path, SHA-256 (re-verified against the file), rows, key, columns, rule."""
    rows = []
    for path in paths:
        meta = hashed.verify(path)
        rows.append(
            {
                "edge": str(path),
                "sha256": meta["sha256"],
                "rows": meta["rows"],
                "key": meta["key"],
                "bytes": Path(path).stat().st_size,
                "columns": ", ".join(
                    f"{c}[{meta['vectors'][c]}]" if c in meta["vectors"] else c
                    for c in meta["columns"]
                ),
                "rule": meta.get("producer", ""),
            }
        )
    return pd.DataFrame(rows)


def pretrained_vs_random_view(table: pd.DataFrame) -> pd.DataFrame:
    """The pretrained-vs-random edge as a reader reads it: one accuracy-with-CI cell per
    backbone and the difference, the rows and classes behind them."""
    return pd.DataFrame(
        {
            "modality": table["modality"],
            "target": table["target"],
            "arch": table["arch"],
            "random init [95% CI]": [
                fmt.with_ci(r.random_accuracy, r.random_ci_low, r.random_ci_high)
                for r in table.itertuples()
            ],
            "pretrained [95% CI]": [
                fmt.with_ci(r.pretrained_accuracy, r.pretrained_ci_low, r.pretrained_ci_high)
                for r in table.itertuples()
            ],
            "Δ [paired 95% CI]": [
                fmt.with_ci(r.delta, r.ci_low, r.ci_high, sign=True) for r in table.itertuples()
            ],
            "p(Δ>0)": table["p_gt0"],
            "n train/test": [f"{r.n_train}/{r.n_test}" for r in table.itertuples()],
            "classes": table["n_classes"],
            "chance": table["chance"],
        }
    )


_STYLE = (
    "body{font-family:sans-serif;font-size:13px;margin:8px}"
    "table{border-collapse:collapse;width:100%}"
    "td,th{border:1px solid #ccc;padding:3px 5px;vertical-align:top;overflow-wrap:break-word}"
    "th{background:#eee}td.mono{font-family:monospace;font-size:11px;word-break:break-all}"
    "td.num{text-align:right;white-space:nowrap}p.note{color:#444;max-width:70em}"
    "p.lead{max-width:70em;margin:4px 0 8px}"
)

# a column of differences: its numbers are written with their sign
_SIGNED = ("Δ", "delta", "gain")

#: where a long identifier may break across lines (after each of these characters): a cell's
#: words stay whole (``overflow-wrap: break-word`` breaks a word only where it alone is wider
#: than its column), and an identifier of `LONG_IDENTIFIER` characters or more, such as
#: ``sim_natural_r05|32|1024``, breaks between its parts, never inside one; a short one
#: (``N_L``, ``Δ_ctrl``) stays whole
_ID_SEPARATORS = re.compile(r"([_|/~])(?=\S)")
LONG_IDENTIFIER = 12


def cell_html(text: str) -> str:
    """A cell's text, escaped, with a line-break opportunity (``<wbr>``) after each identifier
    separator (`_ID_SEPARATORS`) inside a long identifier; the text itself, as copied from the
    page, is unchanged."""
    return "".join(
        _ID_SEPARATORS.sub(r"\1<wbr>", html.escape(part))
        if len(part) >= LONG_IDENTIFIER
        else html.escape(part)
        for part in re.split(r"(\s+)", text)
    )


def footnote_column(table: pd.DataFrame, column: str) -> tuple[pd.DataFrame, list[str]]:
    """A column of long texts as footnote marks: each distinct non-empty text gets a number in
    order of first appearance, its cells the mark (``[1]``), and the notes list the texts
    (``[1] text``). A column of sentences no longer sets the table's width; the rows keep
    which note is theirs."""
    marks: dict[str, int] = {}
    cells = []
    for text in table[column].fillna("").astype(str):
        text = text.strip()
        if text:
            marks.setdefault(text, len(marks) + 1)
        cells.append(f"[{marks[text]}]" if text else "")
    return table.assign(**{column: cells}), [f"[{n}] {text}" for text, n in marks.items()]


def constants_to_lead(
    table: pd.DataFrame, columns: Iterable[str]
) -> tuple[pd.DataFrame, list[str]]:
    """The `columns` whose every row holds one value, stated once above the table (``Every
    row: V features vit, probe seed 42.``) and dropped from it; a column that varies, or a
    table of fewer than two rows, keeps its column."""
    if len(table) < 2:
        return table, []
    same = [c for c in columns if c in table and table[c].astype(str).nunique() == 1]
    if not same:
        return table, []
    stated = ", ".join(f"{c} {table[c].astype(str).iloc[0]}" for c in same)
    return table.drop(columns=same), [f"Every row: {stated}."]


def to_html(
    table: pd.DataFrame,
    *,
    title: str,
    mono: Iterable[str] = ("sha256", "edge"),
    missing: str = "not defined for this row",
    notes: Iterable[str] = (),
    lead: Iterable[str] = (),
) -> str:
    """A standalone HTML page with the table (escaped), every cell written by
    `tacgen_lib.report.format` (3 decimals, signed deltas, integers as integers, a dash for a
    missing value with `missing` as its footnote), `lead` as paragraphs between the title and
    the table (what a reader takes from a long table, before it) and `notes` as paragraphs
    below it."""
    mono = set(mono)
    columns = [str(c) for c in table.columns]
    cells = {c: fmt.column_cells(table[c], sign=str(c).startswith(_SIGNED)) for c in table.columns}
    numeric = {c for c in table.columns if table[c].dtype.kind in "iuf"}
    head = "".join(f"<th>{cell_html(c)}</th>" for c in columns)
    body = []
    for i in range(len(table)):
        row = "".join(
            f'<td class="{"mono" if c in mono else "num" if c in numeric else ""}">'
            f"{cell_html(cells[c][i])}</td>"
            for c in table.columns
        )
        body.append(f"<tr>{row}</tr>")
    notes = list(notes)
    if any(fmt.MISSING in v for v in cells.values()):
        notes.append(f"{fmt.MISSING}: {missing}.")
    foot = "".join(f"<p class='note'>{html.escape(n)}</p>" for n in notes)
    top = "".join(f"<p class='lead'>{html.escape(n)}</p>" for n in lead)
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{_STYLE}</style></head><body><h3>{html.escape(title)}</h3>{top}"
        f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>{foot}"
        "</body></html>\n"
    )
