"""Make one modality's frozen backbone: an official checkpoint, in-workflow pretraining (DINO or
MAE for a ViT, SimCLR for a ResNet) on the pretraining corpus's train split, or the seeded random init (rules
pretrain_backbone and family_backbone; the latter also extracts the backbone's features of
every frame of each probe corpus)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import numpy as np
import pandas as pd
import torch

from tacgen_lib.corpus.splits import assert_trainable, ids_in_split
from tacgen_lib.features.backbones import make_backbone
from tacgen_lib.features.extract import extract_features
from tacgen_lib.features.families import BackboneSpec
from tacgen_lib.features.settings import DinoSettings, MaeSettings, SimclrSettings
from tacgen_lib.features.vit_checkpoint import save_backbone
from tacgen_lib.io import edges, hashed, log
from tacgen_lib.preprocess.frames import decode_frames
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
modality = snakemake.wildcards.modality
pretrain = snakemake.params.pretrain
spec = BackboneSpec.from_config(snakemake.params.backbone)
device = torch_device(snakemake.params.device)
column = "rgb" if modality == "vision" else "tactile_proc"


def train_frames():
    """The pretraining corpora's train frames of this modality (never val or test rows), corpus
    after corpus in the config's order."""
    splits = edges.read(snakemake.input.splits).frame
    parts = []
    for corpus, path in zip(snakemake.params.corpora, snakemake.input.frames, strict=True):
        train_ids = ids_in_split(splits, "train", corpus=corpus)
        frames = edges.read(path).subset(train_ids)
        assert_trainable(frames.ids, splits, rule=snakemake.rule)
        parts.append(decode_frames(frames.frame, column, where=path))
        logger.info("%s: %d train frames", corpus, len(parts[-1]))
    return np.concatenate(parts)


model, curve_rows, how = make_backbone(
    spec,
    image_size=snakemake.params.image_size,
    dino=DinoSettings.from_config(pretrain),
    mae=MaeSettings.from_config(snakemake.params.mae),
    frames=train_frames,
    simclr=SimclrSettings.from_config(snakemake.params.simclr),
    progress=logger.info,
    device=device,
)
logger.info("%s backbone: %s", modality, how)
curve = (
    pd.DataFrame(curve_rows)
    if curve_rows
    else pd.DataFrame({"epoch": pd.Series([], dtype="int64")})
)
curve.insert(
    0, "epoch_id", pd.Series([f"{modality}-{int(e):04d}" for e in curve["epoch"]], dtype=object)
)
save_backbone(model, snakemake.output.weights)
digest = hashed.record_file(snakemake.output.weights, producer=snakemake.rule, kind="weights")
edges.write(snakemake.output.curve, curve, key="epoch_id", producer=snakemake.rule)
logger.info("saved %s backbone, sha256 %s", modality, digest)
# family_backbone: the backbone's features of each probe corpus, column "vit" as in every
# feature edge (the backbone's feature, whatever the family)
for src, dest in zip(
    snakemake.input.get("extract", []), snakemake.output.get("features", []), strict=True
):
    frames = edges.read(src, columns=[column])
    images = decode_frames(frames.frame, column, where=src)
    feats = extract_features(
        model,
        images,
        image_size=snakemake.params.image_size,
        batch_size=snakemake.params.batch_size,
        pool=snakemake.params.pool,
        device=device,
    )
    edges.write(dest, frames.frame[["sample_id"]], {"vit": feats}, producer=snakemake.rule)
    logger.info("%s: %d frames -> features[%d]", dest, len(feats), feats.shape[1])
