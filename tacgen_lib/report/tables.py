"""Tables for the Snakemake report: small, self-contained HTML (no network, no scripts)."""

from __future__ import annotations

import html
from collections.abc import Iterable
from pathlib import Path

import pandas as pd

from tacgen_lib.io import edges

__all__ = ["edge_manifest_table", "to_html"]


def edge_manifest_table(paths: Iterable[str]) -> pd.DataFrame:
    """One row per edge: path, SHA-256 (re-verified against the file), rows, key, columns, rule."""
    rows = []
    for path in paths:
        meta = edges.verify(path)
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


_STYLE = (
    "body{font-family:sans-serif;font-size:13px}table{border-collapse:collapse}"
    "td,th{border:1px solid #ccc;padding:3px 6px;vertical-align:top}th{background:#eee}"
    "td.mono{font-family:monospace;font-size:11px}"
)


def to_html(table: pd.DataFrame, *, title: str, mono: Iterable[str] = ("sha256", "edge")) -> str:
    """A standalone HTML page with the table (escaped)."""
    mono = set(mono)
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in table.columns)
    body = []
    for _, row in table.iterrows():
        cells = "".join(
            f'<td class="{"mono" if c in mono else ""}">{html.escape(str(row[c]))}</td>'
            for c in table.columns
        )
        body.append(f"<tr>{cells}</tr>")
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{_STYLE}</style></head><body><h3>{html.escape(title)}</h3>"
        f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table></body></html>\n"
    )
