"""Train the regime's generators of one corpus x seed on its paired pools (real and re-paired
pairs, every pool size) and sample them for the labelled and test rows (rule
regime_generators)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
import torch
from threadpoolctl import threadpool_limits

from tacgen_lib.generate.regime_generators import pool_generators, regime_generator_settings
from tacgen_lib.generate.regime_sets import (
    RegimeSettings,
    job_regime_sets,
)
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
# one thread per generator, in this process or in each of the job's workers (fork_map): the
# samples do not depend on the cores Snakemake gives the job
torch.set_num_threads(1)
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
# every labelled draw's rows and the test rows (`RegimeSets.labelled_draw`)
rows = sorted(str(i) for i in [*sets.labelled_union(regime.label_draws), *sets.test])
cells = [(int(n_pool), pairing) for n_pool, pairing in params.cells]
with threadpool_limits(1):
    fits = pool_generators(
        vision,
        tactile,
        sets,
        cells,
        settings,
        regime,
        rows=rows,
        seed=seed,
        progress=lambda m: logger.info("%s %s", w.corpus, m),
        workers=snakemake.threads,
        device=torch_device(params.device),
    )
curves = []
for fit, path in zip(fits, snakemake.output.t_gen, strict=True):
    edges.write_vectors(
        path, rows, {"t_gen": fit.t_gen, "t_gen_mean": fit.t_gen_mean}, producer=snakemake.rule
    )
    curves += [
        {
            "eval": f"{fit.n_pool}|{fit.pairing}|step~{point['step']}",
            "corpus": w.corpus,
            "seed": seed,
            "n_pool": fit.n_pool,
            "pairing": fit.pairing,
            **point,
            "best_step": fit.best_step,
        }
        for point in fit.curve
    ]
edges.write(snakemake.output.curves, pd.DataFrame(curves), key="eval", producer=snakemake.rule)
