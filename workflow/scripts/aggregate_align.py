"""Alignment summary (metrics ⋈ benchmark wall time) and its report items (rule aggregate_align)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import io

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from tacgen_lib.align.cell_names import CELL_COLUMNS
from tacgen_lib.io import edges, hashed, log
from tacgen_lib.report import align as align_report
from tacgen_lib.report.write import write_figure, write_table
from tacgen_lib.runtime.benchmarks import benchmark_seconds

logger = log.for_rule(snakemake)
out, params = snakemake.output, snakemake.params

inputs = zip(
    params.cells,
    snakemake.input.metrics,
    snakemake.input.curves,
    snakemake.input.benchmarks,
    strict=True,
)
metrics, curves, seconds = [], [], {}
for cell, metrics_path, curve_path, bench_path in inputs:
    row = edges.read(metrics_path, require={"cell": "str"}).frame
    if list(row["cell"]) != [cell]:
        raise ValueError(
            f"rule aggregate_align: {metrics_path} holds cell(s) {list(row['cell'])}, expected {cell!r}"
        )
    metrics.append(row)
    curve = edges.read(curve_path, require={"step": "int", "val_loss": "float"}).frame
    for col in CELL_COLUMNS:
        curve[col] = row[col].iloc[0]
    curves.append(curve)
    seconds[cell] = benchmark_seconds(bench_path)
metrics = pd.concat(metrics, ignore_index=True)
summary = align_report.alignment_summary(metrics, seconds)
curves = pd.concat(curves, ignore_index=True)

# The per-cell metrics as one hashed edge (reproducible: no wall times) ...
edges.write(out.metrics, metrics.sort_values("cell"), key="cell", producer=snakemake.rule)
# ... and the summary with wall times: a report table, not an edge (wall times vary by run).
sink = io.BytesIO()
pq.write_table(pa.Table.from_pandas(summary, preserve_index=False), sink, compression="zstd")
hashed.atomic_write_bytes(out.summary, sink.getvalue())

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
    write_table(table, out[name], title=title, mono=())
fig = align_report.curve_figure(curves, n_train=params.n_ref)
write_figure(fig, out.curves)
logger.info("%d cells summarised; report items written", len(summary))
