"""Reconstruction and utility of every pixel-generator arm of one corpus x seed on the same
test rows (rule evaluate_pixel_generators)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import numpy as np
import pandas as pd
import torch
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.keys import corpus_labels
from tacgen_lib.corpus.splits import ids_in_split
from tacgen_lib.features.backbones import read_backbone
from tacgen_lib.features.extract import extract_with
from tacgen_lib.features.settings import FeatureSettings
from tacgen_lib.generate.generator_job import GeneratorJob
from tacgen_lib.generate.pixel.frames import resize_frames, tactile_units
from tacgen_lib.generate.pixel.quality import reconstruction_row
from tacgen_lib.generate.pixel.settings import PixelSettings
from tacgen_lib.generate.pixel.utility import REAL_LOWRES, arm_generator, evaluate_arms
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.io import edges, log
from tacgen_lib.preprocess.frames import decode_frames
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
w, params = snakemake.wildcards, snakemake.params
pixel = PixelSettings.from_config(params.settings)
feat = FeatureSettings.for_backbone(params.features, "tactile")
generate = GenerateSettings.from_config(params.generate)
size = pixel.size
job = GeneratorJob.read(snakemake, cv_repeats=generate.cv_repeats)
test_ids = sorted(ids_in_split(job.splits, "test", w.corpus))

# the real frames at the generators' size, through the same ViT: the resolution-matched reference
tactile = edges.read(snakemake.input.tactile, columns=["tactile_proc"])
ids = sorted(tactile.ids)
real_u8 = resize_frames(
    decode_frames(tactile.subset(ids).frame, "tactile_proc", where=snakemake.input.tactile),
    size,
)
backbone = read_backbone(snakemake.input.backbone)
real_lowres = extract_with(backbone, real_u8, feat, device=torch_device(params.device))
arms = {REAL_LOWRES: dict(zip(ids, real_lowres, strict=True))}
position = {sid: k for k, sid in enumerate(ids)}
test_pos = np.array([position[i] for i in test_ids])
real_test = real_u8[test_pos]
real_test_units = tactile_units(real_test)
recon = []
for arm, path in zip(params.arms, snakemake.input.arms, strict=True):
    edge = edges.read(path, require={"frame": "bytes", "frame_cal": "bytes"})
    if sorted(edge.ids) != ids:
        odd = sorted(set(edge.ids) ^ set(ids))[0]
        raise edges.EdgeError(
            f"{path}: sample_id {odd!r} is not in both this arm's frames and "
            f"{snakemake.input.tactile}; rebuild the arm"
        )
    sub = edge.subset(test_ids)
    for column, vectors, name in (("frame", "vit", arm), ("frame_cal", "vit_cal", f"{arm}_cal")):
        arms[name] = dict(zip(edge.ids, edge.vectors[vectors], strict=True))
        gen_test = decode_frames(sub.frame, column, where=path)
        if gen_test.shape[1:3] != size:
            raise ValueError(
                f"{path}: sample_id {test_ids[0]!r} has a {gen_test.shape[1:3]} frame in column "
                f"{column!r}, config pixel.size is {size}; rebuild the arm"
            )
        generator, guidance, steps, calibrated = arm_generator(name)
        row = reconstruction_row(
            real_test,
            gen_test,
            real_test_units,
            tactile_units(gen_test),
            n_resamples=pixel.bootstrap,
            seed=params.probe_seed,
        )
        recon.append(
            {
                "row_id": f"{w.corpus}|seed~{w.seed}|{name}",
                "corpus": w.corpus,
                "seed": int(w.seed),
                "arm": name,
                "generator": generator,
                "guidance": guidance,
                "steps": steps,
                "calibrated": calibrated,
                "gain": float(sub.frame["gain"].iloc[0]),
                "clipped": float(sub.frame["clipped_cal" if calibrated else "clipped"].iloc[0]),
                **row,
            }
        )
        logger.info(
            "%s: pixel-L2 %.4f, SSIM %.3f, std ratio %.3f, high-pass ratio %.3f",
            name,
            row["pixel_l2"],
            row["ssim"],
            row["std_ratio"],
            row["highpass_ratio"],
        )
with threadpool_limits(snakemake.threads):
    rows, perms = evaluate_arms(
        job.targets,
        **job.keywords(),
        arms=arms,
        permutations=generate.permutations,
        reference=params.arms[0],
        labels={"design": corpus_labels(params.corpus)["design"]},
        progress=logger.info,
    )
edges.write(snakemake.output.rows, rows, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.permutations, perms, key="row_id", producer=snakemake.rule)
edges.write(
    snakemake.output.reconstruction, pd.DataFrame(recon), key="row_id", producer=snakemake.rule
)
logger.info("%d utility rows, %d reconstruction rows", len(rows), len(recon))
