"""Every backbone family's probes (the main family's from the probes stage's edges) and the
report page Backbone families (rule aggregate_backbones)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.io import edges, log
from tacgen_lib.probes.backbone_families import rows_from_probes
from tacgen_lib.report import backbones as report
from tacgen_lib.report.write import write_table

logger = log.for_rule(snakemake)
frames = [edges.read(p, require={"row_id": "str"}).frame for p in snakemake.input.rows]
jobs = [tuple(j) for j in snakemake.params.main_jobs]
paths = iter(snakemake.input.main)
for family, labels in snakemake.params.main.items():
    probe_rows = {job: edges.read(next(paths)).frame for job in jobs}
    frames.append(
        rows_from_probes(
            probe_rows, family=family, heads_variant=snakemake.params.heads_variant, labels=labels
        )
    )
    logger.info("%s: the probes stage's headline rows (%d probe jobs)", family, len(jobs))
rows = pd.concat(frames, ignore_index=True).sort_values("row_id", ignore_index=True)
edges.write(snakemake.output.summary, rows, key="row_id", producer=snakemake.rule)
order = snakemake.params.order
notes = report.family_sentences(rows, order)
write_table(
    report.family_table(rows, order),
    snakemake.output.table,
    title="Backbone families: V vs V+T (concat) on each family's frozen features",
    mono=(),
    notes=notes,
)
for note in notes:
    logger.info("%s", note)
