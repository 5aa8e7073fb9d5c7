"""Ingest a real TVL corpus folder, SSVTP or HCT layout (rule ingest_tvl)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from pathlib import Path

from tacgen_lib.corpus.ingest import plan_declared, write_ingested
from tacgen_lib.io import log

logger = log.for_rule(snakemake)
corpus = snakemake.params.corpus
where = f"rule {snakemake.rule}, corpus {corpus['name']!r}"
try:
    plan = plan_declared(Path(snakemake.input.root), corpus)
except (OSError, ValueError) as exc:
    raise type(exc)(f"{where}: {exc}") from exc
logger.info(plan.summary())
for line in plan.warnings():
    logger.warning(line)
progress = log.Progress(logger, len(plan.samples), "samples")
try:
    n_samples, n_sensors = write_ingested(
        plan,
        snakemake.output.samples,
        snakemake.output.sensors,
        producer=snakemake.rule,
        progress=progress.tick,
    )
except (OSError, ValueError) as exc:
    raise type(exc)(f"{where}: {exc}") from exc
logger.info("wrote %d samples, %d sensor backgrounds", n_samples, n_sensors)
