"""Pretrain one modality's backbone with DINO on the train split, or load a checkpoint (rule pretrain_backbone)."""

import pandas as pd
import torch

from tacgen_lib.corpus.splits import assert_trainable, ids_in_split
from tacgen_lib.features.dino import pretrain_dino
from tacgen_lib.features.settings import DinoSettings
from tacgen_lib.features.vit import build_vit, load_pretrained, random_backbone, save_backbone
from tacgen_lib.io import edges, hashed, log
from tacgen_lib.preprocess.frames import decode_frames

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
modality = snakemake.wildcards.modality
backbone, pretrain = snakemake.params.backbone, snakemake.params.pretrain
image_size = snakemake.params.image_size
if backbone.get("checkpoint"):
    model = build_vit(
        backbone["arch"],
        img_size=image_size,
        num_register_tokens=backbone.get("num_register_tokens", 0),
    )
    load_pretrained(model, backbone["checkpoint"])
    curve = pd.DataFrame({"epoch": pd.Series([], dtype="int64")})
    logger.info("loaded official checkpoint %s (no pretraining)", backbone["checkpoint"])
elif int(pretrain["epochs"]) == 0:
    # features.pretrain.epochs: 0 -> the frozen backbone is the seeded random init (README,
    # Backbones: DINO at the default budget did not beat it); no frame is read
    model = random_backbone(backbone["arch"], image_size, seed=int(pretrain["seed"]))
    curve = pd.DataFrame({"epoch": pd.Series([], dtype="int64")})
    logger.info(
        "features.pretrain.epochs is 0: random-init %s backbone (seed %d), no pretraining",
        backbone["arch"],
        pretrain["seed"],
    )
else:
    splits = edges.read(snakemake.input.splits).frame
    train_ids = ids_in_split(splits, "train", corpus=pretrain["corpus"])
    frames = edges.read(snakemake.input.frames).subset(train_ids)
    assert_trainable(frames.ids, splits, rule=snakemake.rule)
    column = "rgb" if modality == "vision" else "tactile_proc"
    images = decode_frames(frames.frame, column, where=snakemake.input.frames)
    logger.info(
        "DINO pretraining of %s (%s) on %d train frames", modality, backbone["arch"], len(images)
    )
    result = pretrain_dino(
        images,
        DinoSettings.from_config(pretrain),
        arch=backbone["arch"],
        image_size=image_size,
        progress=logger.info,
    )
    model = result.backbone()
    # wall-clock seconds stay in the log and the benchmark file: the edge must be reproducible
    curve = pd.DataFrame(result.curve).drop(columns=["seconds"], errors="ignore")
curve.insert(
    0, "epoch_id", pd.Series([f"{modality}-{int(e):04d}" for e in curve["epoch"]], dtype=object)
)
save_backbone(model, snakemake.output.weights)
digest = hashed.record_file(snakemake.output.weights, producer=snakemake.rule)
edges.write(snakemake.output.curve, curve, key="epoch_id", producer=snakemake.rule)
logger.info("saved %s backbone, sha256 %s", modality, digest)
