"""Frozen backbone features and pixel features for every frame of an edge (rules
extract_*_features)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import torch

from tacgen_lib.features.backbones import read_backbone
from tacgen_lib.features.extract import extract_with, pixel_features
from tacgen_lib.features.settings import FeatureSettings
from tacgen_lib.io import edges, log
from tacgen_lib.preprocess.frames import decode_frames
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
column = snakemake.params.column
modality = "vision" if column == "rgb" else "tactile"
settings = FeatureSettings.for_backbone(snakemake.params.features, modality)
frames = edges.read(snakemake.input.frames, columns=[column])
images = decode_frames(frames.frame, column, where=snakemake.input.frames)
model = read_backbone(snakemake.input.weights)
logger.info("%d frames %s -> %s features", len(images), images.shape[1:], settings.pool)
vit = extract_with(model, images, settings, device=torch_device(snakemake.params.device))
pixel = pixel_features(images, size=settings.pixel_size)
edges.write(
    snakemake.output[0],
    frames.frame[["sample_id"]],
    {"vit": vit, "pixel": pixel},
    producer=snakemake.rule,
)
logger.info("wrote vit[%d] and pixel[%d] for %d samples", vit.shape[1], pixel.shape[1], len(vit))
