"""Table of every edge with its verified SHA-256 (rule edge_manifest)."""

from tacgen_lib import log
from tacgen_lib.report_tables import edge_manifest_table, to_html

logger = log.for_rule(snakemake)
table = edge_manifest_table(snakemake.input.edges)
table.to_csv(snakemake.output.tsv, sep="\t", index=False)
with open(snakemake.output.html, "w") as fh:
    fh.write(to_html(table, title="Edge manifest: every Parquet edge of this run, re-verified"))
logger.info("verified %d edges", len(table))
