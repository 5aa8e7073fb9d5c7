"""Utility of generated tactile frames: what their frozen-ViT features add to the probes.

Every pixel generator arm (a generator, a sampling cell, calibrated or not) is judged by the
latent generator's own evaluation (`tacgen_lib.generate.evaluate.evaluate_generator`): V +
T_arm against V, the nonlinear V baseline and ridge V->T, a shuffled-pairing control and the
ViT-feature fidelity, on the same test rows with the same 5,000 fixed-test resamples. This
module only names the arms and relabels that evaluation's rows by arm.

Arm names: ``pix2pix``, ``ddpm_w{w}_s{steps}``, each also with ``_cal`` (the contrast gain
fitted on train rows, `quality.fit_gain`), and ``real_lowres``: the REAL frames area-resized to
the generators' frame size through the same ViT, the best any generator at that size can do
(a gap between V + T_real and it is resolution, not generation).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the rules import this module at parse time: no pandas, scikit-learn
    import numpy as np
    import pandas as pd

    from tacgen_lib.generate.baselines import Baselines, TargetSpec

__all__ = [
    "GENERATORS",
    "REAL_LOWRES",
    "arm_generator",
    "ddpm_arm",
    "evaluate_arms",
]

#: The pixel generators, in the report's order.
GENERATORS = ("pix2pix", "ddpm")
#: The resolution-matched real reference arm.
REAL_LOWRES = "real_lowres"
_DDPM = re.compile(r"^ddpm_w(?P<w>[0-9.]+)_s(?P<steps>[0-9]+)$")


def ddpm_arm(guidance: float | str, steps: int | str) -> str:
    """The arm name of one DDIM cell of the pixel DDPM, e.g. ``ddpm_w1_s10``."""
    return f"ddpm_w{float(guidance):g}_s{int(steps)}"


def arm_generator(arm: str) -> tuple[str, float, int, bool]:
    """(generator, guidance, steps, calibrated) of an arm name; NaN / 0 where not sampled."""
    calibrated = arm.endswith("_cal")
    base = arm.removesuffix("_cal")
    if base in ("pix2pix", REAL_LOWRES):
        return base, float("nan"), 0, calibrated
    m = _DDPM.match(base)
    if m is None:
        raise ValueError(f"unknown pixel generator arm {arm!r}")
    return "ddpm", float(m["w"]), int(m["steps"]), calibrated


def evaluate_arms(
    targets: Sequence[TargetSpec],
    *,
    corpus: str,
    seed: int,
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    arms: Mapping[str, Mapping[str, np.ndarray]],
    baselines: Mapping[str, Baselines],
    permutations: int,
    generator_train_ids: Sequence[str],
    reference: str,
    labels: Mapping[str, object] | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """`evaluate_generator` over the arms (arm -> sample_id -> ViT feature of its frame), its
    rows keyed by arm: columns ``arm``, ``generator``, ``guidance``, ``steps``, ``calibrated``
    replace the latent generator's sampler cell. `reference`: the arm whose CV chooses the
    logistic C of every arm (as the latent generator's reference cell)."""
    from tacgen_lib.generate.evaluate import evaluate_generator

    cells = {arm: (arm, "0", "0") for arm in arms}
    if reference not in cells:
        raise ValueError(f"evaluate_arms: reference arm {reference!r} is not among {list(arms)}")
    rows, perms = evaluate_generator(
        targets,
        corpus=corpus,
        seed=seed,
        vision=vision,
        t_real=t_real,
        t_gen={cells[a]: vectors for a, vectors in arms.items()},
        baselines=baselines,
        permutations=permutations,
        generator_train_ids=generator_train_ids,
        reference=cells[reference],
        labels=labels,
        progress=progress,
    )
    rows, perms = (_by_arm(frame) for frame in (rows, perms))
    rows["row_id"] = [
        f"{corpus}|{t}|seed~{seed}|{a}|{i}"
        for t, a, i in zip(rows["target"], rows["arm"], rows["input"], strict=True)
    ]
    perms["row_id"] = [
        f"{corpus}|seed~{seed}|{a}|{t}|perm~{k}"
        for a, t, k in zip(perms["arm"], perms["target"], perms["permutation"], strict=True)
    ]
    return rows, perms


def _by_arm(frame: pd.DataFrame) -> pd.DataFrame:
    """The sampler column renamed ``arm``, with the arm's generator, guidance, steps and
    calibration beside it (replacing the sampler cell's)."""
    frame = frame.rename(columns={"sampler": "arm"})
    parts = [arm_generator(a) for a in frame["arm"]]
    return frame.assign(
        generator=[p[0] for p in parts],
        guidance=[p[1] for p in parts],
        steps=[p[2] for p in parts],
        calibrated=[p[3] for p in parts],
    )
