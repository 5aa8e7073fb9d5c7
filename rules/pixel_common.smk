"""The pixel generators' names (tacgen_lib.plan.pixel); included by pixel.smk."""

from tacgen_lib.generate.pixel.utility import GENERATORS
from tacgen_lib.plan.pixel import (
    PIXEL_ARM,
    PIXEL_EVAL,
    PIXEL_GENERATOR,
    PIXEL_ITEMS,
    PIXEL_POINT,
    PIXEL_REPORT,
    arm_generator_name,
    fraction_text,
)

PIXEL = PLANS.pixel.settings
PIXEL_CORPORA = PLANS.pixel.corpora
PIXEL_CURVE = PLANS.pixel.curve
PIXEL_CURVE_CORPORA = PLANS.pixel.curve_corpora
# every corpus a pixel generator is trained on: the judged ones, then the curve's
PIXEL_TRAIN_CORPORA = PLANS.pixel.train_corpora
PIXEL_JUDGED_ARMS = PLANS.pixel.judged_arms
# the curve's generator: pix2pix, or the pixel DDPM's first cell
PIXEL_CURVE_ARM = PLANS.pixel.curve_arm

if PLANS.pixel.on:
    TARGETS += [f"{PIXEL_REPORT}/{n}.{e}" for n, e in PIXEL_ITEMS.items()]
    TARGETS += ["results/pixel/summary.parquet"]
    EDGES += PLANS.pixel.eval_files("evaluation.parquet")
    EDGES += PLANS.pixel.eval_files("reconstruction.parquet")
    EDGES += PLANS.pixel.points()
    EDGES += PLANS.pixel.arm_edges()
