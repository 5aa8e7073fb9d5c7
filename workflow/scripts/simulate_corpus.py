"""Simulate one shard of a corpus (rule simulate_corpus)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.corpus.sim.corpus import CorpusSettings, simulate_shard
from tacgen_lib.io import edges, log
from tacgen_lib.io.config import load_yaml

logger = log.for_rule(snakemake)
settings = CorpusSettings.from_config(snakemake.params.corpus)
frame = simulate_shard(
    settings,
    load_yaml(snakemake.input.scenes),
    shard=int(snakemake.wildcards.shard),
    n_shards=int(snakemake.params.n_shards),
    progress=logger.info,
)
digest = edges.write(snakemake.output[0], frame, producer=snakemake.rule)
logger.info("wrote %d samples, sha256 %s", len(frame), digest)
