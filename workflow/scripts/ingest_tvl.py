"""Ingest a real TVL corpus folder, SSVTP or HCT layout (rule ingest_tvl)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from pathlib import Path

from tacgen_lib.corpus.ingest import ingest_hct, ingest_ssvtp
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
corpus = snakemake.params.corpus
root = Path(snakemake.input.root)
if corpus["kind"] == "ssvtp":
    background = Path(corpus["background"]) if corpus.get("background") else None
    samples, sensors = ingest_ssvtp(root, corpus=corpus["name"], background=background)
else:
    samples, sensors = ingest_hct(root, corpus=corpus["name"])
edges.write(snakemake.output.samples, samples, producer=snakemake.rule)
edges.write(snakemake.output.sensors, sensors, key="sensor_id", producer=snakemake.rule)
logger.info("ingested %d samples, %d sensor backgrounds from %s", len(samples), len(sensors), root)
