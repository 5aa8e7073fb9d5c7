"""One family's training-size sweep: raw V vs V+T (concat) on nested training subsets
(rule probe_training_size)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.io import edges, log
from tacgen_lib.probes.family_job import FamilyJob
from tacgen_lib.probes.robustness import RobustnessSettings, training_size_sweep
from tacgen_lib.probes.settings import ProbeSettings

logger = log.for_rule(snakemake)
params = snakemake.params
job = FamilyJob.read(snakemake)
family, rows = job.family, job.rows
robust = RobustnessSettings.from_config(params.robustness)
settings = ProbeSettings.from_config(params.settings, family.kind, 0)
logger.info(
    "%s: training sizes %s of %d train/val rows, subset seeds %s, %d test rows",
    family.name,
    list(robust.size_n_train),
    rows.n_train,
    list(robust.size_seeds),
    rows.n_test,
)


tactile = job.tactile(params.variants, snakemake.input.tactile, only=params.heads_variant)
with threadpool_limits(snakemake.threads):
    frame = training_size_sweep(
        family.name,
        rows,
        vision=job.vision(snakemake.input.vision),
        tactile=tactile[params.heads_variant],
        settings=settings,
        sizes=robust.size_n_train,
        seeds=robust.size_seeds,
        progress=logger.info,
    )
frame["null_corpus"] = job.null_corpus
edges.write(snakemake.output.rows, frame, key="row_id", producer=snakemake.rule)
logger.info("%d points (%s)", len(frame), frame["status"].value_counts().to_dict())
