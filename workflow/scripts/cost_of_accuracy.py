"""Join benchmark files with the metrics each job produced (rule cost_of_accuracy)."""

from pathlib import Path

import pandas as pd

from tacgen_lib.cost.benchmarks import benchmark_seconds
from tacgen_lib.io import edges, log
from tacgen_lib.report.cost import cost_figure, cost_rows
from tacgen_lib.report.write import write_figure, write_table

logger = log.for_rule(snakemake)
simulate = {}
for path in snakemake.input.simulate_bench:
    corpus = Path(path).parent.name
    simulate[corpus] = simulate.get(corpus, 0.0) + benchmark_seconds(path)
manifest = edges.read(snakemake.input.manifest, columns=["corpus"]).frame
table = cost_rows(
    align_summary=pd.read_parquet(snakemake.input.align),
    pretrain=edges.read(snakemake.input.pretrain).frame,
    pretrain_seconds={Path(p).stem: benchmark_seconds(p) for p in snakemake.input.pretrain_bench},
    simulate_seconds=simulate,
    corpus_sizes=manifest["corpus"].value_counts().to_dict(),
)
table.to_csv(snakemake.output.tsv, sep="\t", index=False)
write_table(
    table.round(4),
    snakemake.output.html,
    title="Cost of accuracy: seconds per job against the metric it produced",
    mono=(),
)
write_figure(cost_figure(table), snakemake.output.figure)
logger.info("%d jobs joined with their metrics", len(table))
