"""One point of the generated-fraction curve: InfoNCE heads retrained with generated touch on a
fraction p of their rows, and with a shuffled generator, probed on real touch
(rule pixel_curve_point)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from functools import partial

import pandas as pd
import torch
from threadpoolctl import threadpool_limits

from tacgen_lib.align import grid as align_grid
from tacgen_lib.align.heads import project
from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.align.train import fit_heads
from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.generate.generator_job import job_target_specs
from tacgen_lib.generate.pixel.curve import PAIRINGS, curve_point
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
w, params = snakemake.wildcards, snakemake.params
settings = AlignSettings.from_config(params.align)
device = torch_device(params.device)
fraction, seed = float(w.fraction), int(w.seed)
splits = edges.read(snakemake.input.splits).frame
head_ids = align_grid.cell_ids(splits, corpus=w.corpus, n_train="all", seed=seed)
assert_trainable(head_ids["train"], splits, rule=snakemake.rule, allowed=("train",))
assert_trainable(head_ids["val"], splits, rule=snakemake.rule, allowed=("val",))
targets = job_target_specs(snakemake, splits, cv_repeats=1)
vision = edges.read_vector_map(snakemake.input.v, "vit")
t_real = edges.read_vector_map(snakemake.input.t, "vit")
t_gen = edges.read_vector_map(snakemake.input.t_gen, "vit")
# at p = 0 no row is replaced: one point serves both pairings
pairings = PAIRINGS if fraction > 0 else PAIRINGS[:1]
parts = []
with threadpool_limits(snakemake.threads):
    for pairing in pairings:
        logger.info("%s p=%g %s: training heads (tau %s)", w.corpus, fraction, pairing, params.tau)
        part = curve_point(
            targets,
            corpus=w.corpus,
            generator=params.arm,
            seed=seed,
            fraction=fraction,
            pairing=pairing,
            vision=vision,
            t_real=t_real,
            t_gen=t_gen,
            head_ids=head_ids,
            fit_heads=partial(
                fit_heads, tau=float(params.tau), seed=seed, settings=settings, device=device
            ),
            project=partial(project, device=device),
        )
        for r in part.itertuples():
            logger.info(
                "  %s: %d rows generated, V+T delta %+.3f [%+.3f, %+.3f], top1 %.3f",
                r.target,
                r.n_replaced,
                r.delta,
                r.ci_low,
                r.ci_high,
                r.top1_v2t,
            )
        parts.append(part)
edges.write(snakemake.output[0], pd.concat(parts), key="row_id", producer=snakemake.rule)
