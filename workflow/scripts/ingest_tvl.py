"""Ingest a real TVL corpus folder, SSVTP or HCT layout (rule ingest_tvl)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from pathlib import Path

from tacgen_lib.corpus.ingest import ingest_declared
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
root = Path(snakemake.input.root)
samples, sensors = ingest_declared(root, snakemake.params.corpus)
edges.write(snakemake.output.samples, samples, producer=snakemake.rule)
edges.write(snakemake.output.sensors, sensors, key="sensor_id", producer=snakemake.rule)
logger.info("ingested %d samples, %d sensor backgrounds from %s", len(samples), len(sensors), root)
