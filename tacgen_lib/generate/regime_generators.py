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
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from tacgen_lib.corpus.derangement import sattolo_cycle
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.regime_sets import PAIRINGS, RegimeSets, RegimeSettings, pool_steps
from tacgen_lib.generate.sampling import generate
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.generate.train import GeneratorFit, fit_generator
from tacgen_lib.runtime.workers import fork_map

__all__ = [
    "PAIRINGS",
    "PoolGenerator",
    "pool_generators",
    "pool_pairs",
    "pool_steps",
    "regime_generator_settings",
    "sample_regime",
    "sample_seed",
    "train_pool_generator",
]


def sample_seed(seed: int, n_pool: int, k: int) -> int:
    """The noise seed of sample k of a regime generator: sample 0's is the one-sample arm's
    (seed x 1,000,003 + N_P), the others step by a prime."""
    return int(seed) * 1_000_003 + int(n_pool) + int(k) * 7_919


def regime_generator_settings(
    generate_cfg: GenerateSettings, regime: RegimeSettings
) -> GenerateSettings:
    """The diffusion generator of config ``generate`` with the regime's step cap and batch: the
    cap of a pool of at most ``regime.steps_reference_pool`` rows; `pool_generators` gives each
    pool its own (`regime_sets.pool_steps`)."""
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
    device: Any,
) -> GeneratorFit:
    """`fit_generator` on the pool's pairs (`pool_pairs`), seeded by `seed`, on `device`."""
    train, val = pool_pairs(pool, val_fraction=val_fraction, pairing=pairing, seed=seed)

    def block(pairs: list[tuple[str, str]]) -> tuple[np.ndarray, np.ndarray]:
        return (
            feature_block(tactile, [t for _, t in pairs]),
            feature_block(vision, [v for v, _ in pairs]),
        )

    t_tr, v_tr = block(train)
    t_va, v_va = block(val)
    return fit_generator(
        t_tr, v_tr, t_va, v_va, settings, seed=seed, progress=progress, device=device
    )


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


@dataclass(frozen=True)
class PoolGenerator:
    """One trained and sampled generator of a corpus x seed: its samples and its curve."""

    n_pool: int
    pairing: str
    t_gen: np.ndarray  # (rows, d) float32, in the order of the rows asked for
    t_gen_mean: np.ndarray  # (rows, d) float32: the mean of K samples (the ladder's gen_mean)
    curve: list[dict]  # step, train_loss, val_loss per evaluation
    best_step: int
    steps_run: int
    best_val_loss: float


def pool_generators(
    vision: Mapping[str, np.ndarray],
    tactile: Mapping[str, np.ndarray],
    sets: RegimeSets,
    cells: Sequence[tuple[int, str]],
    settings: GenerateSettings,
    regime: RegimeSettings,
    *,
    rows: Sequence[str],
    seed: int,
    progress: Callable[[str], Any] | None = None,
    workers: int = 1,
    device: Any,
) -> list[PoolGenerator]:
    """The generator of every (pool size, pairing) cell (`train_pool_generator` on the pool
    of that size, `settings` with its ``steps`` grown to the pool's cap,
    `regime_sets.pool_steps`), each sampled ``regime.gen_mean_samples`` times for `rows`
    (`sample_regime`, noise seeded by `sample_seed`): the first sample is the ``v_tgen`` arm's
    T_gen, the mean of all the ``gen_mean`` rung's; in the order of `cells`.

    The cells are independent (each seeds its own training and sampling): `workers` forked
    processes train them (`runtime.workers.fork_map`, the same samples for any number of
    workers), the largest pools first.
    """
    say = progress or (lambda _m: None)

    def one(cell: tuple[int, str]) -> PoolGenerator:
        n_pool, pairing = int(cell[0]), cell[1]
        pool = sets.pool_ids(n_pool)
        say(f"seed {seed}: pool of {len(pool)} ({pairing} pairs)")
        fit = train_pool_generator(
            vision,
            tactile,
            pool,
            replace(settings, steps=pool_steps(settings.steps, n_pool, regime)),
            val_fraction=regime.pool_val_fraction,
            pairing=pairing,
            seed=seed,
            progress=lambda m: say(f"pool {n_pool} {pairing}: {m}"),
            device=device,
        )
        samples = [
            sample_regime(
                fit,
                vision,
                rows,
                steps=regime.sampling_steps,
                guidance=regime.guidance,
                seed=sample_seed(seed, n_pool, k),
            )
            for k in range(int(regime.gen_mean_samples))
        ]
        # the ladder's gen_mean: the generator's conditional mean, estimated by K samples
        t_gen_mean = np.mean(np.stack(samples).astype(np.float64), axis=0).astype(np.float32)
        say(
            f"pool {n_pool} {pairing}: best step {fit.best_step} of {fit.steps_run}, "
            f"val loss {fit.best_val_loss:.4f}"
        )
        return PoolGenerator(
            n_pool,
            pairing,
            samples[0],
            t_gen_mean,
            [dict(point) for point in fit.curve],
            int(fit.best_step),
            int(fit.steps_run),
            float(fit.best_val_loss),
        )

    on_cpu = str(device) == "cpu"
    return fork_map(one, cells, workers if on_cpu else 1, cost=lambda cell: float(cell[0]))
