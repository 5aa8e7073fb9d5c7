"""Train the latent V->T generator of one corpus x seed on its train split (rule train_generator)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
import torch
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable, ids_in_split
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.generate.train import fit_generator, save_generator
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
w = snakemake.wildcards
settings = GenerateSettings.from_config(snakemake.params.settings)
seed = int(w.seed)
splits = edges.read(snakemake.input.splits, require={"split": "str", "corpus": "str"}).frame
train_ids = sorted(ids_in_split(splits, "train", w.corpus))
val_ids = sorted(ids_in_split(splits, "val", w.corpus))
# The generator learns from the alignment-train split only; val rows only steer early stopping.
assert_trainable(train_ids, splits, rule=snakemake.rule, allowed=("train",))
assert_trainable(val_ids, splits, rule=snakemake.rule, allowed=("val",))
vision = edges.read(snakemake.input.v, columns=["vit"], require={"vit": "vector"})
tactile = edges.read(snakemake.input.t, columns=["vit"], require={"vit": "vector"})


def pairs(ids):
    return tactile.subset(ids).vectors["vit"], vision.subset(ids).vectors["vit"]


t_tr, v_tr = pairs(train_ids)
t_va, v_va = pairs(val_ids)
logger.info(
    "%s seed %d: %d train / %d val pairs, V[%d] -> T[%d]; %d x %d residual MLP, %s-prediction, "
    "%s schedule T=%d",
    w.corpus,
    seed,
    len(train_ids),
    len(val_ids),
    v_tr.shape[1],
    t_tr.shape[1],
    settings.blocks,
    settings.hidden,
    settings.prediction,
    settings.schedule,
    settings.train_steps,
)
with threadpool_limits(snakemake.threads):
    fit = fit_generator(
        t_tr,
        v_tr,
        t_va,
        v_va,
        settings,
        seed=seed,
        progress=logger.info,
        device=torch_device(snakemake.params.device),
    )
save_generator(fit, snakemake.output.weights, producer=snakemake.rule)
curve = pd.DataFrame(fit.curve)
curve.insert(0, "eval", [f"step~{s}" for s in curve["step"]])
curve["corpus"], curve["seed"] = w.corpus, seed
edges.write(snakemake.output.curve, curve, key="eval", producer=snakemake.rule)
logger.info(
    "best step %d of %d (early stop: %s), val loss %.4f",
    fit.best_step,
    fit.steps_run,
    fit.stopped_early,
    fit.best_val_loss,
)
