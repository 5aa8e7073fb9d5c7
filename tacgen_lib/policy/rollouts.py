"""Held-out rollouts: each condition's grip force per episode, then the physics-only lift."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
import pandas as pd

from tacgen_lib.io.edges import Edge
from tacgen_lib.policy import bc, data, task
from tacgen_lib.policy.settings import PolicySettings

__all__ = ["grip_forces", "roll_out"]


def grip_forces(
    condition: str, palpation: Edge, policy: bc.BCPolicy | None, settings: PolicySettings
) -> dict[str, float]:
    """episode_id -> grip force (N) of `condition` for every held-out episode.

    oracle: the privileged window centre; vision_ceiling: the best force given the size alone;
    learned conditions: the policy's output on that condition's features."""
    frame = palpation.frame
    test = (frame["split"] == "test").to_numpy()
    ids = frame["episode_id"].to_numpy()[test]
    if condition == "oracle":
        f = frame["oracle_force"].to_numpy()[test]
    elif condition == "vision_ceiling":
        f = frame["ceiling_force"].to_numpy()[test]
    else:
        if policy is None:
            raise ValueError(f"condition {condition!r} needs a trained policy")
        vec = palpation.vectors
        null = bc.null_pairing(
            frame["episode_id"].to_numpy(), frame["split"].to_numpy(), settings.seed
        )
        x = bc.condition_features(
            condition, vec["v"], vec["t_raw"], vec[f"t_aligned~{settings.heads_seed}"], null
        )
        f = policy.grip_force(x[test])
    return {str(i): float(v) for i, v in zip(ids, f, strict=True)}


def roll_out(
    settings: PolicySettings,
    scene_decl: Mapping,
    episodes: pd.DataFrame,
    forces: Mapping[str, float],
    progress: Callable[[int], None] | None = None,
) -> pd.DataFrame:
    """One row per episode: the force, success, failure mode and the measurements."""
    lift = data.compile_phase(scene_decl, settings, "lift")
    rows = []
    for n, row in enumerate(episodes.to_dict("records")):
        ep = data.episode_from_row(row)
        if ep.episode_id not in forces:
            raise KeyError(f"episode {ep.episode_id!r} has no grip force (not a held-out episode?)")
        f = float(np.clip(forces[ep.episode_id], 0.0, 60.0))  # the pad motors' range
        out = task.rollout(lift, ep, f)
        rows.append(
            {
                "episode_id": ep.episode_id,
                "grip_force": f,
                "success": bool(out.success),
                "mode": out.mode,
                "lift": out.lift,
                "slip": out.slip,
                "peak_force": out.peak_force,
                "steps": out.steps,
            }
        )
        if progress is not None:
            progress(n + 1)
    return pd.DataFrame(rows)
