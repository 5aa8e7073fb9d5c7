"""Train the regime's generators of one corpus x seed on its paired pools (real and re-paired
pairs, every pool size) and sample them for the labelled and test rows (rule
regime_generators)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
import torch
from threadpoolctl import threadpool_limits

from tacgen_lib.generate.regime_generators import (
    regime_generator_settings,
    sample_regime,
    train_pool_generator,
)
from tacgen_lib.generate.regime_sets import (
    RegimeSettings,
    job_regime_sets,
)
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
w, params = snakemake.wildcards, snakemake.params
regime = RegimeSettings.from_config(params.regime)
settings = regime_generator_settings(GenerateSettings.from_config(params.generate), regime)
seed = int(w.seed)
splits = edges.read(snakemake.input.splits, require={"split": "str", "corpus": "str"}).frame
# the generators learn from pool rows only: never a labelled or a test row
sets = job_regime_sets(splits, w.corpus, regime, seed, rule=snakemake.rule)


vision, tactile = (
    edges.read_vector_map(snakemake.input.v, "vit"),
    edges.read_vector_map(snakemake.input.t, "vit"),
)
rows = sorted(str(i) for i in [*sets.labelled, *sets.test])
curves = []
for (n_pool, pairing), path in zip(params.cells, snakemake.output.t_gen, strict=True):
    pool = sets.pool_ids(int(n_pool))
    logger.info("%s seed %d: pool of %d (%s pairs)", w.corpus, seed, len(pool), pairing)
    with threadpool_limits(snakemake.threads):
        fit = train_pool_generator(
            vision,
            tactile,
            pool,
            settings,
            val_fraction=regime.pool_val_fraction,
            pairing=pairing,
            seed=seed,
            progress=logger.info,
        )
        t_gen = sample_regime(
            fit,
            vision,
            rows,
            steps=regime.sampling_steps,
            guidance=regime.guidance,
            seed=seed * 1_000_003 + int(n_pool),
        )
    edges.write_vectors(path, rows, {"t_gen": t_gen}, producer=snakemake.rule)
    logger.info(
        "pool %d %s: best step %d of %d, val loss %.4f",
        int(n_pool),
        pairing,
        fit.best_step,
        fit.steps_run,
        fit.best_val_loss,
    )
    for point in fit.curve:
        curves.append(
            {
                "eval": f"{n_pool}|{pairing}|step~{point['step']}",
                "corpus": w.corpus,
                "seed": seed,
                "n_pool": int(n_pool),
                "pairing": pairing,
                **point,
                "best_step": fit.best_step,
            }
        )
edges.write(snakemake.output.curves, pd.DataFrame(curves), key="eval", producer=snakemake.rule)
