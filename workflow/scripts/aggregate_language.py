"""The tactile-to-language evidence of every corpus and the report page Touch to language
(rule aggregate_language)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.io import edges, log
from tacgen_lib.report import language as report
from tacgen_lib.report.write import write_table

logger = log.for_rule(snakemake)
rows = pd.concat(
    [edges.read(p, require={"row_id": "str"}).frame for p in snakemake.input.rows],
    ignore_index=True,
).sort_values("row_id", ignore_index=True)
edges.write(snakemake.output.evidence, rows, key="row_id", producer=snakemake.rule)
notes = report.language_sentences(rows)
write_table(
    report.language_table(rows),
    snakemake.output.table,
    title=(
        "Touch to language: forced-choice accuracy of the tactile adapter on the test rows "
        f"({snakemake.params.cell})"
    ),
    mono=(),
    notes=notes,
)
for note in notes:
    logger.info("%s", note)
