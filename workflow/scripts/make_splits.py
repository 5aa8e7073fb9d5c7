"""Fix the train/val/test splits before any feature is computed (rule make_splits)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.corpus.splits import SplitSettings, make_splits
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
settings = SplitSettings.from_config(snakemake.params.splits)
# corpora split by object group their rows by appearance_id and stratify on mass
columns = ["corpus", "stratum", "scale"] + (["appearance_id", "mass"] if settings.by_object else [])
manifest = edges.read(snakemake.input.manifest, columns=columns).frame
splits = make_splits(manifest, settings)
edges.write(snakemake.output[0], splits, producer=snakemake.rule)
for (corpus, split), n in splits.groupby(["corpus", "split"]).size().items():
    logger.info("%s %s: %d", corpus, split, n)
