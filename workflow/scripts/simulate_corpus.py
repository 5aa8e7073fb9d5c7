"""Simulate one shard of a corpus (rule simulate_corpus), or of every natural corpus of the
regime's rho grid at once, their physics and touch simulated once (rule
simulate_natural_grid); one output per corpus, in the order of params.corpora."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.corpus.sim.corpus import simulate_shards
from tacgen_lib.corpus.sim.samples import CorpusSettings
from tacgen_lib.io import edges, log
from tacgen_lib.io.config import load_yaml

logger = log.for_rule(snakemake)
settings = [CorpusSettings.from_config(c) for c in snakemake.params.corpora]
frames = simulate_shards(
    settings,
    load_yaml(snakemake.input.scenes),
    shard=int(snakemake.wildcards.shard),
    n_shards=int(snakemake.params.n_shards),
    progress=logger.info,
)
for cfg, path, frame in zip(settings, snakemake.output, frames, strict=True):
    digest = edges.write(path, frame, producer=snakemake.rule)
    logger.info("wrote %d samples of %s, sha256 %s", len(frame), cfg.name, digest)
