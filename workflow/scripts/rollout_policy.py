"""Lift one shard of held-out episodes with one cell's grip forces, physics only (rule rollout_policy)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
import torch

from tacgen_lib.io import edges, log
from tacgen_lib.io.config import load_yaml
from tacgen_lib.policy import bc, data, rollouts
from tacgen_lib.policy.settings import PolicySettings
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
settings = PolicySettings.from_config(snakemake.params.settings)
w = snakemake.wildcards
shard = int(w.shard)
episodes = pd.concat(
    [edges.read(p).frame for p in snakemake.input.episodes], ignore_index=True
).sort_values("episode_id", ignore_index=True)
edge = edges.read(snakemake.input.palpation)
policy = bc.load_bc(snakemake.input.weights[0]) if snakemake.input.weights else None
if policy is not None:
    policy.net.to(torch_device(snakemake.params.device))  # grip forces computed where it is
forces = rollouts.grip_forces(w.condition, edge, policy, settings)
idx = data.shard_indices(len(episodes), settings.rollout_shards, shard)
scene = load_yaml(snakemake.input.scenes)["grasp_lift"]
progress = log.Progress(logger, len(idx), "rollouts")
frame = rollouts.roll_out(settings, scene, episodes.iloc[list(idx)], forces, progress=progress.tick)
frame.insert(1, "condition", w.condition)
edges.write(snakemake.output[0], frame, key="episode_id", producer=snakemake.rule)
logger.info(
    "%s: %d episodes, success %.3f",
    w.condition,
    len(frame),
    frame["success"].mean() if len(frame) else 0,
)
