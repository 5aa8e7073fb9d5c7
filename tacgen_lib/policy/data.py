"""Episode edges of the policy stage: collection (rule collect_demos), the split guard.

An episode edge has one row per episode (key `episode_id`): its split (`train` for
demonstrations, `test` for held-out episodes), visible appearance, invisible physics, the
window, the oracle's and the vision ceiling's forces, the palpation's RGB and tactile frames
(PNG bytes) and the oracle demonstration's outcome. Demonstrations and held-out episodes are
drawn from disjoint seeded streams (`set_seed`), so no held-out object is ever a demo object.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
import pandas as pd

from tacgen_lib.corpus.sim.scenes import Scene
from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.io.images import encode_png
from tacgen_lib.policy import oracle, palpation, task
from tacgen_lib.policy.settings import PolicySettings

__all__ = [
    "EPISODE_SETS",
    "set_seed",
    "shard_indices",
    "collect_episodes",
    "episode_from_row",
    "episode_splits",
    "training_rows",
    "compile_phase",
]

#: episode set -> (split, id prefix, seed offset)
EPISODE_SETS: dict[str, tuple[str, str, int]] = {
    "demos": ("train", "demo", 0),
    "heldout": ("test", "held", 1_000_003),
}


def set_seed(settings: PolicySettings, episode_set: str) -> int:
    return settings.seed + EPISODE_SETS[episode_set][2]


def set_size(settings: PolicySettings, episode_set: str) -> int:
    return settings.n_demos if episode_set == "demos" else settings.n_heldout


def shard_indices(n: int, shards: int, shard: int) -> range:
    """Episode indices of shard `shard` of `shards` (contiguous blocks)."""
    if not 0 <= shard < shards:
        raise ValueError(f"shard {shard} not in [0, {shards})")
    bounds = np.linspace(0, n, shards + 1).round().astype(int)
    return range(int(bounds[shard]), int(bounds[shard + 1]))


def compile_phase(scene_decl: Mapping, settings: PolicySettings, phase: str) -> task.GraspTask:
    """The task compiled with exactly one phase's declared effects ('lift' or 'palpation')."""
    effects = settings.lift_effects if phase == "lift" else settings.palpation_effects
    scene: Scene = task.phase_scene(dict(scene_decl), list(effects), settings.timestep)
    return task.GraspTask(scene, settings)


def collect_episodes(
    settings: PolicySettings,
    scene_decl: Mapping,
    episode_set: str,
    shard: int,
    shards: int,
    progress: Callable[[int], None] | None = None,
) -> pd.DataFrame:
    """Simulate one shard of an episode set: sample, palpate (frames), and for demonstrations
    roll out the oracle (its outcome is recorded; the stage checks its success)."""
    split, prefix, _ = EPISODE_SETS[episode_set]
    seed = set_seed(settings, episode_set)
    palp = compile_phase(scene_decl, settings, "palpation")
    lift = compile_phase(scene_decl, settings, "lift")
    optics = palpation.PadOptics(settings.tactile_size)
    rows = []
    idx = shard_indices(set_size(settings, episode_set), shards, shard)
    for n, i in enumerate(idx):
        ep = task.sample_episode(settings, seed, i, prefix)
        obs = palpation.palpate(palp, ep, optics, noise_seed=seed * 7919 + i)
        lo, hi = task.window(ep, settings)
        f_oracle = oracle.oracle_force(ep, settings)
        demo = task.rollout(lift, ep, f_oracle) if episode_set == "demos" else None
        row = {
            "episode_id": ep.episode_id,
            "split": split,
            "size": ep.size,
            "red": ep.rgba[0],
            "green": ep.rgba[1],
            "blue": ep.rgba[2],
            "texture": ep.texture,
            "density": ep.density,
            "mass": ep.mass,
            "friction": ep.friction,
            "stiffness": ep.stiffness,
            "crush_limit": ep.crush_limit,
            "window_lo": lo,
            "window_hi": hi,
            "oracle_force": f_oracle,
            "ceiling_force": oracle.vision_ceiling_force(settings, ep.size, settings.seed),
            "held_0": bool(obs.held[0]),
            "held_1": bool(obs.held[-1]),
            "demo_outcome": demo.mode if demo is not None else "",
            "rgb": encode_png(obs.rgb) if obs.rgb is not None else b"",
        }
        for name in palpation.frame_names(len(settings.palpation_forces)):
            row[name] = encode_png(obs.frames[name]) if name in obs.frames else b""
        rows.append(row)
        if progress is not None:
            progress(n + 1)
    return pd.DataFrame(rows)


def episode_from_row(row: Mapping) -> task.Episode:
    """Rebuild an Episode from an episode-edge row (bit-exact: floats are stored as float64)."""
    return task.Episode(
        episode_id=str(row["episode_id"]),
        size=float(row["size"]),
        rgba=(float(row["red"]), float(row["green"]), float(row["blue"]), 1.0),
        texture=str(row["texture"]),
        density=float(row["density"]),
        friction=float(row["friction"]),
        stiffness=float(row["stiffness"]),
        crush_limit=float(row["crush_limit"]),
    )


def episode_splits(frame: pd.DataFrame) -> pd.DataFrame:
    """The split table (`sample_id`, `split`) of episodes, for corpus.splits.assert_trainable."""
    return pd.DataFrame({"sample_id": frame["episode_id"], "split": frame["split"]})


def training_rows(frame: pd.DataFrame, ids, *, rule: str) -> np.ndarray:
    """Boolean mask of `ids` rows in `frame`, after refusing any held-out id (LeakageError)."""
    assert_trainable(ids, episode_splits(frame), rule=rule)
    return frame["episode_id"].isin(set(ids)).to_numpy()
