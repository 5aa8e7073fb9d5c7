"""Train one pixel generator (Pix2Pix or the pixel DDPM) on a corpus's train rows, early-stopped
on its val rows (rule train_pixel_generator)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import torch

from tacgen_lib.corpus.splits import assert_trainable, ids_in_split
from tacgen_lib.generate.pixel.frames import PairedEdges, rgb_units, tactile_units
from tacgen_lib.generate.pixel.settings import PixelSettings
from tacgen_lib.generate.pixel.weights import save_pixel_generator
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
w, pixel = snakemake.wildcards, PixelSettings.from_config(snakemake.params.settings)
size = pixel.size
splits = edges.read(snakemake.input.splits).frame
train_ids = sorted(ids_in_split(splits, "train", w.corpus))
val_ids = sorted(ids_in_split(splits, "val", w.corpus))
assert_trainable(train_ids, splits, rule=snakemake.rule, allowed=("train",))
assert_trainable(val_ids, splits, rule=snakemake.rule, allowed=("val",))

paired = PairedEdges(snakemake.input.samples, snakemake.input.tactile)


def units(ids):
    rgb, tac = paired.frames(ids, size)
    return rgb_units(rgb), tactile_units(tac)


(rgb_tr, tac_tr), (rgb_val, tac_val) = units(train_ids), units(val_ids)
logger.info(
    "%s %s seed %s: %d train / %d val frames at %s",
    w.corpus,
    w.generator,
    w.seed,
    len(train_ids),
    len(val_ids),
    size,
)
if w.generator == "pix2pix":
    from tacgen_lib.generate.pixel.pix2pix import fit_pix2pix as fit_generator

    model_settings = pixel.pix2pix
else:
    from tacgen_lib.generate.pixel.ddpm import fit_pixel_ddpm as fit_generator

    model_settings = pixel.ddpm
fit = fit_generator(
    rgb_tr,
    tac_tr,
    rgb_val,
    tac_val,
    model_settings,
    seed=int(w.seed),
    progress=logger.info,
    device=torch_device(snakemake.params.device),
)
save_pixel_generator(fit, snakemake.output.weights, kind=w.generator, producer=snakemake.rule)
curve = fit.curve.assign(eval=[f"step~{int(s)}" for s in fit.curve["step"]])
edges.write(snakemake.output.curve, curve, key="eval", producer=snakemake.rule)
logger.info(
    "best step %d of %d (stopped early: %s), best val %.5f",
    fit.best_step,
    fit.steps_run,
    fit.stopped_early,
    fit.best_val,
)
