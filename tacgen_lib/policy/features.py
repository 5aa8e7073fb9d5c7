"""Palpation features (rule palpate): frozen backbones + alignment heads on episode frames.

V is the frozen vision backbone's feature of the RGB context frame. T is built per tactile
moment (each probe's squeeze and heft): both pads' frames are background-subtracted with the
alignment's preprocessing variant against their pad's own background, passed through the
frozen tactile backbone, and averaged over the two pads (they see the same contact, mirrored);
the moments are concatenated in a fixed order.

Aligned T: each moment's tactile feature is projected by the alignment heads **trained on the
paired press corpus** (the align stage's cell, one per alignment seed), not by heads trained on
the demonstrations' own frames. Why: (1) the demonstrations are few (96 in the paper's
protocol), far too few to train a contrastive head without overfitting it; (2) the claim under
test is that a representation learned from passive paired data carries the physics a policy
needs: training heads on the demos would fold the policy's own supervision into the
representation; (3) no extra training rule has to be guarded against the held-out episodes:
the press corpus's heads never saw an episode. The cost is a domain shift (gripper pads vs the
press gel: a different background and imprint scale), which the report states beside the result.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from torch import nn

from tacgen_lib.align.heads import AlignHeads, project
from tacgen_lib.features.extract import extract_with
from tacgen_lib.features.settings import FeatureSettings
from tacgen_lib.preprocess.background import background_subtract

__all__ = ["tactile_moments", "palpation_features"]


def tactile_moments(frame_names: Sequence[str]) -> list[str]:
    """Moments (e.g. 'squeeze_0') in column order, from names 'tactile_<moment>_<pad>'."""
    out: list[str] = []
    for name in frame_names:
        moment = name[len("tactile_") :].rsplit("_", 2)[0]
        if moment not in out:
            out.append(moment)
    return out


def palpation_features(
    rgb: np.ndarray,
    frames: Mapping[str, np.ndarray],
    backgrounds: Mapping[str, np.ndarray],
    vision: nn.Module,
    tactile: nn.Module,
    heads: Mapping[str, AlignHeads],
    *,
    variant: str,
    reads: Mapping[str, FeatureSettings],
    device: Any,
) -> dict[str, np.ndarray]:
    """V (N, d_v), T raw (N, moments x d_t) and T aligned per heads key (N, moments x 128).

    rgb: (N, H, W, 3); frames: column 'tactile_<moment>_<pad>' -> (N, h, w, 3);
    backgrounds: pad name -> (h, w, 3). reads: modality ("vision", "tactile") -> how its
    backbone's features are read (`FeatureSettings.for_backbone`: image size, batch, pool;
    `extract.extract_with`), as the extraction rules read them. `device` (a torch device or its
    name): where the backbones and heads run (`extract_with`, `project`).
    """
    v = extract_with(vision, rgb, reads["vision"], device=device)
    moments = tactile_moments(list(frames))
    raw, aligned = [], {k: [] for k in heads}
    for moment in moments:
        per_pad = []
        for name, imgs in frames.items():
            if not name.startswith(f"tactile_{moment}_"):
                continue
            pad = name[len(f"tactile_{moment}_") :]
            proc = np.stack([background_subtract(f, backgrounds[pad], variant) for f in imgs])
            per_pad.append(extract_with(tactile, proc, reads["tactile"], device=device))
        t = np.mean(per_pad, axis=0).astype(np.float32)
        raw.append(t)
        for key, h in heads.items():
            aligned[key].append(project(h, v, t, device=device)[1])
    out = {"v": v, "t_raw": np.hstack(raw)}
    for key, parts in aligned.items():
        out[f"t_aligned~{key}"] = np.hstack(parts)
    return out
