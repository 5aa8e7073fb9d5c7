"""Pretrained vs random-init backbone, linear probe with a bootstrap CI (rule pretrained_vs_random)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
import torch
from threadpoolctl import threadpool_limits

from tacgen_lib.features.backbones import random_init
from tacgen_lib.features.extract import extract_with
from tacgen_lib.features.families import BackboneSpec
from tacgen_lib.features.pretrained_vs_random import pretrained_vs_random
from tacgen_lib.features.settings import DinoSettings, FeatureSettings, PretrainedVsRandomSettings
from tacgen_lib.io import edges, log
from tacgen_lib.preprocess.frames import decode_frames
from tacgen_lib.report.tables import pretrained_vs_random_view
from tacgen_lib.report.write import write_table
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
params = snakemake.params
features = FeatureSettings.from_config(params.features)
pretrain = DinoSettings.from_config(params.pretrain)
check = PretrainedVsRandomSettings.from_config(params.check)
corpus = check.corpus
splits = edges.read(snakemake.input.splits).frame
manifest = edges.read(snakemake.input.manifest).frame.set_index("sample_id")
rows = []
for modality, column in (("vision", "rgb"), ("tactile", "tactile_proc")):
    frames = edges.read(snakemake.input[modality], columns=[column])
    pre = edges.read(snakemake.input[f"pretrained_{modality}"]).subset(frames.ids)
    target = check.targets[modality]
    labels = manifest.loc[frames.ids, target].astype(str).to_numpy()
    split = splits.set_index("sample_id").loc[frames.ids, "split"].to_numpy()
    train, test = (split == "train").nonzero()[0], (split == "test").nonzero()[0]
    images = decode_frames(frames.frame, column, where=snakemake.input[modality])
    arch = params.archs[modality]
    read = FeatureSettings.for_backbone(params.features, modality)  # its image size and pool
    rand = extract_with(
        random_init(arch, read.image_size, seed=pretrain.seed),
        images,
        read,
        device=torch_device(params.device),
    )
    with threadpool_limits(snakemake.threads):
        res = pretrained_vs_random(
            pre.vectors["vit"],
            rand,
            labels,
            train,
            test,
            C_grid=params.C,
            seed=pretrain.seed,
            n_resamples=check.bootstrap,
            sample_ids=frames.ids,
        )
    rows.append(
        {
            "check_id": f"{corpus}/{modality}/{target}",
            "corpus": corpus,
            "modality": modality,
            "target": target,
            "arch": arch,
            **res,
        }
    )
    logger.info(
        "%s/%s: pretrained %.3f vs random %.3f, delta %.3f [%.3f, %.3f]",
        modality,
        target,
        res["pretrained_accuracy"],
        res["random_accuracy"],
        res["delta"],
        res["ci_low"],
        res["ci_high"],
    )
table = pd.DataFrame(rows)
edges.write(snakemake.output.table, table, key="check_id", producer=snakemake.rule)
specs = {m: BackboneSpec.from_config(params.features["backbones"][m]) for m in check.targets}
made = "; ".join(f"{m}: {s.label(pretrain.epochs)}" for m, s in specs.items())
title = f"Pretrained vs random-init backbone ({made}): logistic probe accuracy on the test split"
unlearnt = [m for m, s in specs.items() if not s.pretrains(pretrain.epochs)]
if unlearnt:
    title += (
        f". The {' and '.join(unlearnt)} backbone IS the seeded random init (no pretraining: "
        "features.pretrain.epochs 0 for DINO, or objective random), so its Δ = 0 by "
        "construction; the accuracies are what its features attain. Why DINO is off: "
        "docs/features.md, and the pretrain_epochs knob of the cost-of-accuracy sweep "
        "(config/cost.yaml)"
    )
write_table(pretrained_vs_random_view(table), snakemake.output.html, title=title, mono=())
