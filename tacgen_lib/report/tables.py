"""Tables for the Snakemake report: small, self-contained HTML (no network, no scripts)."""

from __future__ import annotations

import html
from collections.abc import Iterable
from pathlib import Path

import pandas as pd

from tacgen_lib.io import hashed
from tacgen_lib.report import format as fmt

__all__ = ["edge_manifest_table", "pretrained_vs_random_view", "to_html"]


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
    "td,th{border:1px solid #ccc;padding:3px 5px;vertical-align:top;overflow-wrap:anywhere}"
    "th{background:#eee}td.mono{font-family:monospace;font-size:11px;word-break:break-all}"
    "td.num{text-align:right;white-space:nowrap}p.note{color:#444;max-width:70em}"
    "p.lead{max-width:70em;margin:4px 0 8px}"
)

# a column of differences: its numbers are written with their sign
_SIGNED = ("Δ", "delta", "gain")


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
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = []
    for i in range(len(table)):
        row = "".join(
            f'<td class="{"mono" if c in mono else "num" if c in numeric else ""}">'
            f"{html.escape(cells[c][i])}</td>"
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
