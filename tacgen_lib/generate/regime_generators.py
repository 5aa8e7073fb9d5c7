"""The regime's generators: the latent diffusion generator trained on an unlabelled paired pool
(`tacgen_lib.generate.regime`), with its pairs kept or broken, then sampled for the rows the
regime's probes read.

A pool of N_P (V, T) rows is split in order: its first ``ceil(pool_val_fraction x N_P)``
rows (at least 1) only steer early stopping, the rest train. The ``shuffled`` generator is
trained on the same rows with T re-paired by a Sattolo cycle of each part (no row keeps its
own touch): it sees the same marginals and learns no V-T link.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from tacgen_lib.corpus.derangement import sattolo_cycle
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.regime_sets import PAIRINGS, RegimeSettings
from tacgen_lib.generate.sampling import generate
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.generate.train import GeneratorFit, fit_generator

__all__ = [
    "PAIRINGS",
    "pool_pairs",
    "regime_generator_settings",
    "sample_regime",
    "train_pool_generator",
]


def regime_generator_settings(
    generate_cfg: GenerateSettings, regime: RegimeSettings
) -> GenerateSettings:
    """The diffusion generator of config ``generate`` with the regime's step cap and batch."""
    return replace(generate_cfg, steps=int(regime.steps), batch_size=int(regime.batch_size))


def pool_pairs(
    pool: Sequence[str], *, val_fraction: float, pairing: str, seed: int
) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """(train, val) lists of (vision sample_id, tactile sample_id) pairs of a pool.

    ``real``: each row with its own touch; ``shuffled``: touch re-paired by a seeded Sattolo
    cycle within train and within val (every pair broken when a part has >= 2 rows).
    """
    if pairing not in PAIRINGS:
        raise ValueError(f"pool_pairs: pairing must be one of {PAIRINGS}, got {pairing!r}")
    pool = [str(i) for i in pool]
    if len(pool) < 2:
        raise ValueError(
            f"pool_pairs: a pool needs >= 2 rows (train + early stopping), got {len(pool)}"
        )
    n_val = min(max(1, math.ceil(val_fraction * len(pool))), len(pool) - 1)
    val, train = pool[:n_val], pool[n_val:]
    rng = np.random.default_rng([int(seed), 0x73687566])

    def pair(ids: list[str]) -> list[tuple[str, str]]:
        if pairing == "real" or len(ids) < 2:
            return [(i, i) for i in ids]
        perm = sattolo_cycle(len(ids), rng)
        return [(ids[k], ids[int(perm[k])]) for k in range(len(ids))]

    return pair(train), pair(val)


def train_pool_generator(
    vision: Mapping[str, np.ndarray],
    tactile: Mapping[str, np.ndarray],
    pool: Sequence[str],
    settings: GenerateSettings,
    *,
    val_fraction: float,
    pairing: str,
    seed: int,
    progress: Callable[[str], Any] | None = None,
) -> GeneratorFit:
    """`fit_generator` on the pool's pairs (`pool_pairs`), seeded by `seed`."""
    train, val = pool_pairs(pool, val_fraction=val_fraction, pairing=pairing, seed=seed)

    def block(pairs: list[tuple[str, str]]) -> tuple[np.ndarray, np.ndarray]:
        return (
            feature_block(tactile, [t for _, t in pairs]),
            feature_block(vision, [v for v, _ in pairs]),
        )

    t_tr, v_tr = block(train)
    t_va, v_va = block(val)
    return fit_generator(t_tr, v_tr, t_va, v_va, settings, seed=seed, progress=progress)


def sample_regime(
    fit: GeneratorFit,
    vision: Mapping[str, np.ndarray],
    ids: Sequence[str],
    *,
    steps: int,
    guidance: float,
    seed: int,
) -> np.ndarray:
    """Generated tactile features (float32, rows in `ids` order) by DDIM with `steps` steps at
    `guidance`, noise seeded by `seed`."""
    weights = fit.weights()
    cond = feature_block(vision, [str(i) for i in ids])
    return generate(
        weights,
        cond,
        sampler="ddim",
        steps=int(steps),
        guidance=float(guidance),
        seed=int(seed),
        eta=weights.settings.eta,
        batch=weights.settings.batch,
    )
