"""Held-out-scale diagnosis of one family: its headline comparison (raw V vs V+T, concat) on a
random within-scale split of the training rows, under every protocol variant
(rule probe_within_scale)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.io import edges, log
from tacgen_lib.probes.family_job import FamilyJob
from tacgen_lib.probes.protocol import run_family, tidy
from tacgen_lib.probes.robustness import RobustnessSettings
from tacgen_lib.probes.settings import ProbeSettings

logger = log.for_rule(snakemake)
params = snakemake.params
robust = RobustnessSettings.from_config(params.robustness)
# Only train/val rows are re-split; the corpus's test rows are never read.
job = FamilyJob.read(snakemake, within_scale=(robust.within_test_fraction, robust.within_seed))
family, rows = job.family, job.rows
assert_trainable(rows.test_ids, job.splits, rule=snakemake.rule, allowed=("train", "val"))
logger.info(
    "%s: within-scale split of the train/val rows: %d train, %d test (fraction %.2f, seed %d)",
    family.name,
    rows.n_train,
    rows.n_test,
    robust.within_test_fraction,
    robust.within_seed,
)


vision = job.vision(snakemake.input.vision)
tactile = job.tactile(params.variants, snakemake.input.tactile, only=params.heads_variant)
frames = []
with threadpool_limits(snakemake.threads):
    for protocol in robust.protocols:
        result = run_family(
            family.name,
            rows,
            vision=vision,
            tactile=tactile,
            aligned={},
            fusions=["concat"],
            heads_variant=params.heads_variant,
            settings=ProbeSettings.from_config(
                params.settings, family.kind, robust.within_seed, protocol=protocol
            ),
            labels={"split": "within_scale", "null_corpus": job.null_corpus},
            progress=logger.info,
            headline_only=True,
            controls=False,
        )
        frames.append(result.rows)
frame = tidy(pd.concat(frames, ignore_index=True))
edges.write(snakemake.output.rows, frame, key="row_id", producer=snakemake.rule)
logger.info("%d rows", len(frame))
