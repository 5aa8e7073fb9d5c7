"""Every row's generated tactile frame for one pixel-generator arm, its contrast calibration
(gain fitted on train rows) and the frozen tactile ViT's features of both frames
(rule sample_pixel_generator)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import numpy as np
import pandas as pd
import torch

from tacgen_lib.corpus.splits import ids_in_split
from tacgen_lib.features.backbones import read_backbone
from tacgen_lib.features.extract import extract_with
from tacgen_lib.features.settings import FeatureSettings
from tacgen_lib.generate.pixel.frames import (
    PairedEdges,
    rgb_units,
    tactile_units,
    to_uint8_tactile,
)
from tacgen_lib.generate.pixel.quality import fit_gain
from tacgen_lib.generate.pixel.settings import PixelSettings
from tacgen_lib.generate.pixel.utility import arm_generator
from tacgen_lib.generate.pixel.weights import load_pixel_generator
from tacgen_lib.io import edges, log
from tacgen_lib.io.images import encode_png
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
w = snakemake.wildcards
pixel = PixelSettings.from_config(snakemake.params.settings)
feat = FeatureSettings.for_backbone(snakemake.params.features, "tactile")
size = pixel.size
generator, guidance, steps, _ = arm_generator(w.arm)

paired = PairedEdges(snakemake.input.samples, snakemake.input.tactile)
ids = sorted(paired.samples.ids)
rgb_u8, tac_u8 = paired.frames(ids, size)
rgb = rgb_units(rgb_u8)
fit = load_pixel_generator(snakemake.input.weights)
device = torch_device(snakemake.params.device)
fit.model.to(device)  # the sampler runs where the model is
logger.info("%s: generating %d frames at %s with %s", w.corpus, len(ids), size, w.arm)
if generator == "pix2pix":
    from tacgen_lib.generate.pixel.pix2pix import translate

    gen = translate(fit.model, rgb, batch=pixel.batch)
else:
    from tacgen_lib.generate.pixel.ddpm import sample_pixel_ddpm
    from tacgen_lib.generate.schedules import make_schedule

    s = fit.settings
    gen = sample_pixel_ddpm(
        fit.model,
        rgb,
        schedule=make_schedule(s.schedule, s.train_steps),
        prediction=s.prediction,
        steps=steps,
        guidance=guidance,
        eta=s.eta,
        seed=int(w.seed),
        batch=pixel.batch,
        scale=fit.scale,
    )
splits = edges.read(snakemake.input.splits).frame
train = set(ids_in_split(splits, "train", w.corpus))
is_train = np.array([i in train for i in ids])
# the calibration sees train rows only: never a test row
gain = fit_gain(gen[is_train], tactile_units(tac_u8[is_train]))
frames, clipped = to_uint8_tactile(gen)
frames_cal, clipped_cal = to_uint8_tactile(np.float32(gain) * gen)
logger.info(
    "gain %.3f (train rows); values outside the frame range: %.4f raw, %.4f calibrated",
    gain,
    clipped,
    clipped_cal,
)
backbone = read_backbone(snakemake.input.backbone)


def vit(images):
    return extract_with(backbone, images, feat, device=device)


table = pd.DataFrame(
    {
        "sample_id": ids,
        "frame": [encode_png(f) for f in frames],
        "frame_cal": [encode_png(f) for f in frames_cal],
        "gain": gain,
        "clipped": clipped,
        "clipped_cal": clipped_cal,
    }
)
edges.write(
    snakemake.output.frames,
    table,
    {"vit": vit(frames), "vit_cal": vit(frames_cal)},
    producer=snakemake.rule,
)
logger.info("wrote %d frames and their ViT features", len(ids))
