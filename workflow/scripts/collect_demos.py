"""Simulate one shard of demonstrations or held-out episodes (rule collect_demos)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.io import edges, log
from tacgen_lib.io.config import load_yaml
from tacgen_lib.policy import data
from tacgen_lib.policy.settings import PolicySettings

logger = log.for_rule(snakemake)
settings = PolicySettings.from_config(snakemake.params.settings)
episode_set, shard = snakemake.wildcards.episode_set, int(snakemake.wildcards.shard)
scene = load_yaml(snakemake.input.scenes)["grasp_lift"]
n = len(data.shard_indices(data.set_size(settings, episode_set), settings.collect_shards, shard))
progress = log.Progress(logger, n, "episodes")
frame = data.collect_episodes(
    settings, scene, episode_set, shard, settings.collect_shards, progress=progress.tick
)
if episode_set == "demos":
    failed = frame[frame["demo_outcome"] != "success"]
    logger.info("oracle demonstrations: %d/%d succeeded", len(frame) - len(failed), len(frame))
edges.write(snakemake.output[0], frame, key="episode_id", producer=snakemake.rule)
logger.info("%s shard %d: %d episodes", episode_set, shard, len(frame))
