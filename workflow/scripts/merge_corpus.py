"""Concatenate a simulated corpus's shards; write its sensor backgrounds (rule merge_corpus)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.corpus.sim.corpus import sensor_backgrounds
from tacgen_lib.corpus.sim.samples import CorpusSettings
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
settings = CorpusSettings.from_config(snakemake.params.corpus)
shards = [edges.read(path).frame for path in snakemake.input.shards]
for shard, (path, frame) in enumerate(zip(snakemake.input.shards, shards, strict=True)):
    if len(frame) == 0 and shard < settings.n:
        raise ValueError(
            f"rule merge_corpus: {path}: shard {shard} has no rows, expected the samples i with "
            f"i % {len(shards)} == {shard} (sample_id '{settings.name}-{shard:06d}' first); "
            "delete the shard and rerun simulate_corpus"
        )
samples = pd.concat(shards, ignore_index=True).sort_values("sample_id", ignore_index=True)
n_expected = settings.n
if len(samples) != n_expected:
    raise ValueError(
        f"rule merge_corpus: corpus {snakemake.wildcards.corpus!r} has {len(samples)} samples "
        f"across {len(shards)} shards, config asks for n={n_expected}"
    )
sensors = sensor_backgrounds(settings)
unknown = set(samples["sensor_id"]) - set(sensors["sensor_id"])
if unknown:
    raise ValueError(f"rule merge_corpus: sensor(s) {sorted(unknown)} have no background image")
edges.write(snakemake.output.samples, samples, producer=snakemake.rule)
edges.write(snakemake.output.sensors, sensors, key="sensor_id", producer=snakemake.rule)
logger.info("merged %d shards: %d samples, %d sensors", len(shards), len(samples), len(sensors))
