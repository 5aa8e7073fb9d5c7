"""Simulate one shard of a corpus (rule simulate_corpus)."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from tacgen_lib import edges, log  # noqa: E402
from tacgen_lib.config import load_yaml  # noqa: E402
from tacgen_lib.sim.corpus import simulate_shard  # noqa: E402

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
