"""Alignment heads of one knob setting and seed; the test rows' retrieval ranks (rule cost_train_heads).

The alignment knobs of the cost sweep (config cost.knobs): `align_steps` trains with a budget
of `{value}` optimiser steps (early stopping as in the default), `align_n` on `{value}` training
rows. Every other setting is config `align`'s, τ is the probes' heads τ. The ranks (one row per
test sample) let the points carry a bootstrap CI over the test rows.
"""

from dataclasses import replace

import numpy as np
import pandas as pd
import torch
from threadpoolctl import threadpool_limits

from tacgen_lib.align import heads
from tacgen_lib.align.retrieval import retrieval_ranks
from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
w, params = snakemake.wildcards, snakemake.params
settings = AlignSettings.from_config(params.settings)
n_train = heads.parse_n_train(params.n_train)
if w.knob == "align_steps":
    settings = replace(settings, budget="steps", steps=int(w.value))
elif w.knob == "align_n":
    n_train = heads.parse_n_train(w.value)
else:
    raise ValueError(f"rule {snakemake.rule}: {w.knob!r} is not an alignment knob")
seed, feature = int(w.seed), settings.feature

vision = edges.read(snakemake.input.v, columns=[feature], require={feature: "vector"})
tactile = edges.read(snakemake.input.t, columns=[feature], require={feature: "vector"})
splits = edges.read(snakemake.input.splits, require={"split": "str", "corpus": "str"}).frame
ids = heads.cell_ids(splits, corpus=params.corpus, n_train=n_train, seed=seed)
logger.info(
    "%s = %s, seed %d: %d train / %d val / %d test rows of %s, budget %s (%s)",
    w.knob, w.value, seed, len(ids["train"]), len(ids["val"]), len(ids["test"]), params.corpus,
    settings.budget, settings.steps if settings.budget == "steps" else settings.epochs,
)  # fmt: skip
with threadpool_limits(snakemake.threads):
    # fit_cell refuses held-out rows first (corpus.splits.assert_trainable)
    fit = heads.fit_cell(
        vision, tactile, splits, ids, tau=float(params.tau), seed=seed, settings=settings,
        rule=snakemake.rule, progress=logger.info,
    )  # fmt: skip
test_ids = sorted(ids["test"])
z_v, z_t = heads.project(
    fit.result,
    vision.subset(test_ids).vectors[feature],
    tactile.subset(test_ids).vectors[feature],
)
n_tr = len(ids["train"])
default_steps = (
    settings.steps
    if AlignSettings.from_config(params.settings).budget == "steps"
    else int(params.settings["epochs"]) * (n_tr // min(int(params.settings["batch_size"]), n_tr))
)
ranks = pd.DataFrame(
    {
        "sample_id": test_ids,
        "rank_v2t": retrieval_ranks(z_v, z_t).astype(np.int64),
        "rank_t2v": retrieval_ranks(z_t, z_v).astype(np.int64),
        "steps_run": fit.metrics["steps_run"],
        "n_train_rows": n_tr,
        "default_steps": default_steps,
    }
)
edges.write(snakemake.output.ranks, ranks, key="sample_id", producer=snakemake.rule)
logger.info(
    "%s = %s, seed %d: %d steps run, test top-1 v2t %.3f, median rank %.1f",
    w.knob, w.value, seed, fit.metrics["steps_run"], float(np.mean(ranks["rank_v2t"] <= 1)),
    float(np.median(ranks["rank_v2t"])),
)  # fmt: skip
