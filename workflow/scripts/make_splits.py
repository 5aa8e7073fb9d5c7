"""Fix the train/val/test splits before any feature is computed (rule make_splits)."""

from tacgen_lib.corpus.splits import make_splits
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
cfg = snakemake.params.splits
manifest = edges.read(snakemake.input.manifest, columns=["corpus", "stratum", "scale"]).frame
splits = make_splits(
    manifest, seed=cfg["seed"], fractions=cfg["fractions"], by_scale=cfg.get("by_scale")
)
edges.write(snakemake.output[0], splits, producer=snakemake.rule)
for (corpus, split), n in splits.groupby(["corpus", "split"]).size().items():
    logger.info("%s %s: %d", corpus, split, n)
