"""Train the InfoNCE heads of one alignment grid cell; retrieval on its test split (rule train_heads)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
import torch
from threadpoolctl import threadpool_limits

from tacgen_lib.align import checkpoint as align_checkpoint
from tacgen_lib.align import grid as align_grid
from tacgen_lib.align.cell_names import cell_name
from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
w = snakemake.wildcards
settings = AlignSettings.from_config(snakemake.params.settings)
feature = settings.feature
seed, n_train = int(w.seed), align_grid.parse_n_train(w.n_train)

vision = edges.read(snakemake.input.v, columns=[feature], require={feature: "vector"})
tactile = edges.read(snakemake.input.t, columns=[feature], require={feature: "vector"})
splits = edges.read(snakemake.input.splits, require={"split": "str", "corpus": "str"}).frame
ids = align_grid.cell_ids(splits, corpus=w.corpus, n_train=n_train, seed=seed)
logger.info(
    "%s: %d train / %d val / %d test rows, %s features v[%d] t[%d]",
    w.corpus,
    len(ids["train"]),
    len(ids["val"]),
    len(ids["test"]),
    feature,
    vision.vectors[feature].shape[1],
    tactile.vectors[feature].shape[1],
)
with threadpool_limits(snakemake.threads):
    fit = align_grid.fit_cell(
        vision,
        tactile,
        splits,
        ids,
        tau=float(w.tau),
        seed=seed,
        settings=settings,
        rule=snakemake.rule,
        progress=logger.info,
        device=torch_device(snakemake.params.device),
    )
cell = cell_name(w.corpus, w.variant, seed, w.tau, w.n_train)
row = {
    "cell": cell,
    "corpus": w.corpus,
    "variant": w.variant,
    "seed": seed,
    "tau": w.tau,
    "n_train": w.n_train,
    "feature": feature,
    **fit.metrics,
}
align_checkpoint.save_heads(fit.result, snakemake.output.heads, producer=snakemake.rule)
edges.write(snakemake.output.curve, fit.curve, key="eval", producer=snakemake.rule)
edges.write(snakemake.output.ranks, fit.ranks, key="sample_id", producer=snakemake.rule)
edges.write(snakemake.output.metrics, pd.DataFrame([row]), key="cell", producer=snakemake.rule)
logger.info(
    "%s: best step %d of %d (early stop: %s), test top1 v2t %.3f t2v %.3f (chance %.3f)",
    cell,
    fit.metrics["best_step"],
    fit.metrics["steps_run"],
    fit.metrics["stopped_early"],
    fit.metrics["top1_v2t"],
    fit.metrics["top1_t2v"],
    fit.metrics["chance_top1"],
)
