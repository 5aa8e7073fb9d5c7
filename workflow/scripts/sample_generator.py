"""Generated tactile features for every row of a corpus, every sampling cell of one generator
(rule sample_generator).

The generator is read once; its cells (sampler x guidance x steps) run in forked one-thread
workers, one per thread of the job (`tacgen_lib.runtime.workers.fork_map`), each computing what
a one-thread job of that cell computes, so the edges do not depend on the thread count. Each
cell's wall and CPU seconds go to its own benchmark-format file (the Generation summary's and
the cost page's per-cell seconds).

On the CPU (config device cpu, or auto without a GPU) it imports no torch and no pandas: the
weights are read and sampled in numpy (`tacgen_lib.generate.inference`), the edges read and
written through pyarrow. On a GPU the torch twin samples (`tacgen_lib.generate.sampling_torch`:
the same noise and steps, equal within float rounding), its cells one after another in the job's
own process (a forked copy cannot use the parent's CUDA context)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import time

import numpy as np
from threadpoolctl import threadpool_limits

from tacgen_lib.generate.inference import read_generator
from tacgen_lib.generate.sampling import generate
from tacgen_lib.generate.sampling_cells import cell_seed, guidance_passes
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.benchmarks import write_benchmark
from tacgen_lib.runtime.device import torch_device
from tacgen_lib.runtime.workers import fork_map

logger = log.for_rule(snakemake)
w = snakemake.wildcards
cells = [tuple(c) for c in snakemake.params.cells]  # (sampler, guidance, steps), output order
weights = read_generator(snakemake.input.weights)
ids, vit = edges.read_vectors(snakemake.input.v, "vit")
order = np.argsort(ids, kind="stable")  # rows by sample_id
ids, cond = ids[order], vit[order]
logger.info(
    "%d rows, %d cells on %d thread(s), eta=%s",
    len(ids),
    len(cells),
    snakemake.threads,
    weights.settings.eta,
)

# "cpu" resolves without importing torch; a CPU torch device samples in numpy too
device = None if snakemake.params.device == "cpu" else torch_device(snakemake.params.device)
if device is not None and device.type == "cpu":
    device = None
if device is not None:
    logger.info("sampling on %s", device)


def sample_cell(i: int) -> tuple[float, tuple[int, int]]:
    """Cell i: its generated vectors to its edge, its seconds to its benchmark file."""
    sampler, guidance, steps = cells[i]
    wall0, cpu0 = time.perf_counter(), time.process_time()
    cell = dict(
        sampler=sampler,
        steps=int(steps),
        guidance=float(guidance),
        seed=cell_seed(w.seed, guidance, steps),
        eta=weights.settings.eta,
        batch=weights.settings.batch,
    )
    if device is None:
        with threadpool_limits(1):
            t_gen = generate(weights, cond, **cell)
    else:
        from tacgen_lib.generate.sampling_torch import generate_torch

        t_gen = generate_torch(weights, cond, device=device, **cell)
    edges.write_vectors(snakemake.output.t_gen[i], ids, {"t_gen": t_gen}, producer=snakemake.rule)
    wall = time.perf_counter() - wall0
    write_benchmark(snakemake.output.seconds[i], wall=wall, cpu=time.process_time() - cpu0)
    return wall, t_gen.shape


done = fork_map(
    sample_cell,
    range(len(cells)),
    snakemake.threads if device is None else 1,
    # the longest cells first: network passes x steps
    cost=lambda i: len(guidance_passes(cells[i][1])) * int(cells[i][2]),
)
for (sampler, guidance, steps), (wall, shape) in zip(cells, done, strict=True):
    logger.info(
        "%s %s steps, w=%s: %d x %d generated vectors in %.1f s",
        sampler,
        steps,
        guidance,
        *shape,
        wall,
    )
