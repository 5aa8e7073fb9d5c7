"""Simulate one shard of a corpus (rule simulate_corpus)."""

from tacgen_lib.corpus.sim.corpus import simulate_shard
from tacgen_lib.io import edges, log
from tacgen_lib.io.config import load_yaml

logger = log.for_rule(snakemake)
frame = simulate_shard(
    snakemake.params.corpus,
    load_yaml(snakemake.input.scenes),
    shard=int(snakemake.wildcards.shard),
    n_shards=int(snakemake.params.n_shards),
    progress=logger.info,
)
digest = edges.write(snakemake.output[0], frame, producer=snakemake.rule)
logger.info("wrote %d samples, sha256 %s", len(frame), digest)
