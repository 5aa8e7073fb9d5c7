"""Frozen-backbone and aligned features of every episode's palpation frames (rule palpate)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
import torch

from tacgen_lib.align import checkpoint as align_checkpoint
from tacgen_lib.features.backbones import read_backbone
from tacgen_lib.features.settings import FeatureSettings
from tacgen_lib.io import edges, log
from tacgen_lib.policy.features import palpation_features
from tacgen_lib.policy.palpation import PAD_NAMES, frame_names, pad_background
from tacgen_lib.policy.settings import PolicySettings
from tacgen_lib.preprocess.frames import decode_frames
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
settings = PolicySettings.from_config(snakemake.params.settings)
# each backbone read as the extraction rules read it: its own image size and pool
reads = {
    m: FeatureSettings.for_backbone(snakemake.params.features, m) for m in ("vision", "tactile")
}
names = frame_names(len(settings.palpation_forces))
parts = [edges.read(p).frame for p in snakemake.input.episodes]
episodes = pd.concat(parts, ignore_index=True).sort_values("episode_id", ignore_index=True)
keyed = episodes.rename(columns={"episode_id": "sample_id"})
where = f"rule palpate, {', '.join(snakemake.input.episodes)}"
rgb = decode_frames(keyed, "rgb", where=where)
frames = {n: decode_frames(keyed, n, where=where) for n in names}
backgrounds = {
    pad: pad_background(settings.seed, k, settings.tactile_size) for k, pad in enumerate(PAD_NAMES)
}
heads = {
    seed: align_checkpoint.load_heads(path)
    for seed, path in zip(snakemake.params.align_seeds, snakemake.input.heads, strict=True)
}
logger.info(
    "%d episodes, %d tactile frames each, %d alignment seeds", len(episodes), len(names), len(heads)
)
out = palpation_features(
    rgb,
    frames,
    backgrounds,
    read_backbone(snakemake.input.vision),
    read_backbone(snakemake.input.tactile),
    heads,
    variant=settings.heads_variant,
    reads=reads,
    device=torch_device(snakemake.params.device),
)
labels = episodes[
    [
        "episode_id",
        "split",
        "size",
        "mass",
        "friction",
        "stiffness",
        "window_lo",
        "window_hi",
        "oracle_force",
        "ceiling_force",
        "held_0",
        "held_1",
    ]
]
edges.write(snakemake.output[0], labels, out, key="episode_id", producer=snakemake.rule)
logger.info("features: %s", {k: v.shape[1] for k, v in out.items()})
