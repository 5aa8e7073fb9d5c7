"""Table of every edge with its verified SHA-256 (rule edge_manifest)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.io import log
from tacgen_lib.report.tables import edge_manifest_table
from tacgen_lib.report.write import write_table

logger = log.for_rule(snakemake)
table = edge_manifest_table(snakemake.input.edges)
table.to_csv(snakemake.output.tsv, sep="\t", index=False)
write_table(
    table, snakemake.output.html, title="Edge manifest: every Parquet edge of this run, re-verified"
)
logger.info("verified %d edges", len(table))
