"""Alignment summary (metrics ⋈ benchmark wall time) and its report items (rule aggregate_align)."""

import io

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from tacgen_lib import align_report, edges, log
from tacgen_lib.report_tables import to_html

logger = log.for_rule(snakemake)
out, params = snakemake.output, snakemake.params

metrics = []
for path in snakemake.input.metrics:
    row = edges.read(path, require={"cell": "str"}).frame
    if list(row["cell"]) != [align_report.cell_from_path(path)]:
        raise ValueError(f"rule aggregate_align: {path} holds cell(s) {list(row['cell'])}")
    metrics.append(row)
metrics = pd.concat(metrics, ignore_index=True)
seconds = {
    align_report.cell_from_path(p): align_report.benchmark_seconds(p)
    for p in snakemake.input.benchmarks
}
summary = align_report.alignment_summary(metrics, seconds)

curves = []
for path in snakemake.input.curves:
    cell = align_report.cell_from_path(path)
    curve = edges.read(path, require={"step": "int", "val_loss": "float"}).frame
    for col in align_report.CELL_COLUMNS:
        curve[col] = metrics.loc[metrics["cell"] == cell, col].iloc[0]
    curves.append(curve)
curves = pd.concat(curves, ignore_index=True)

# The per-cell metrics as one hashed edge (reproducible: no wall times) ...
edges.write(out.metrics, metrics.sort_values("cell"), key="cell", producer=snakemake.rule)
# ... and the summary with wall times: a report table, not an edge (wall times vary by run).
sink = io.BytesIO()
pq.write_table(pa.Table.from_pandas(summary, preserve_index=False), sink, compression="zstd")
edges.atomic_write_bytes(out.summary, sink.getvalue())

tables = {
    "tau": (
        align_report.tau_ablation_table(summary, params.n_ref),
        f"τ ablation: test-split retrieval, mean ± sd over seeds (N = {params.n_ref})",
    ),
    "n_scaling": (
        align_report.n_scaling_table(summary, params.tau_ref),
        f"N scaling: test-split retrieval and train time, mean ± sd over seeds (τ = {params.tau_ref})",
    ),
    "seeds": (
        align_report.seed_table(summary),
        "Retrieval on the held-out test split per grid cell, mean ± sd over seeds",
    ),
}
for name, (table, title) in tables.items():
    edges.atomic_write_bytes(out[name], to_html(table, title=title, mono=()).encode())
fig = align_report.curve_figure(curves, n_train=params.n_ref)
buf = io.BytesIO()
fig.savefig(buf, format="png", dpi=110, metadata={"Software": None})
edges.atomic_write_bytes(out.curves, buf.getvalue())
logger.info("%d cells summarised; report items written", len(summary))
