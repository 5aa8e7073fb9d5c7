"""Generated tactile features for every row of a corpus, one sampling cell (rule sample_generator).

On the CPU (config device cpu, or auto without a GPU) it imports no torch and no pandas: the
weights are read and sampled in numpy (`tacgen_lib.generate.inference`), the edges read and
written through pyarrow. On a GPU the torch twin samples (`tacgen_lib.generate.sampling_torch`:
the same noise and steps, equal within float rounding)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import numpy as np
from threadpoolctl import threadpool_limits

from tacgen_lib.generate.inference import read_generator
from tacgen_lib.generate.sampling import generate
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
w = snakemake.wildcards
weights = read_generator(snakemake.input.weights)
ids, vit = edges.read_vectors(snakemake.input.v, "vit")
order = np.argsort(ids, kind="stable")  # rows by sample_id
ids, cond = ids[order], vit[order]
# Sampling noise: seeded by the generator seed and the cell, so each cell is reproducible.
seed = int(w.seed) * 1_000_003 + int(w.steps) * 101 + int(round(float(w.guidance) * 1000))
logger.info(
    "%d rows, %s with %s steps, guidance w=%s, eta=%s",
    len(ids),
    w.sampler,
    w.steps,
    w.guidance,
    weights.settings.eta,
)
cell = dict(
    sampler=w.sampler,
    steps=int(w.steps),
    guidance=float(w.guidance),
    seed=seed,
    eta=weights.settings.eta,
    batch=weights.settings.batch,
)
# "cpu" resolves without importing torch
device = None if snakemake.params.device == "cpu" else torch_device(snakemake.params.device)
if device is None or device.type == "cpu":
    with threadpool_limits(snakemake.threads):
        t_gen = generate(weights, cond, **cell)
else:
    from tacgen_lib.generate.sampling_torch import generate_torch

    logger.info("sampling on %s", device)
    t_gen = generate_torch(weights, cond, device=device, **cell)
edges.write_vectors(snakemake.output.t_gen, ids, {"t_gen": t_gen}, producer=snakemake.rule)
logger.info("wrote %d x %d generated vectors", *t_gen.shape)
