"""Probe V+T_gen (and its controls) for every cell of one generator against the corpus's
baselines (rule evaluate_generator)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.keys import corpus_labels
from tacgen_lib.generate.evaluate import evaluate_generator
from tacgen_lib.generate.generator_job import GeneratorJob
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
params = snakemake.params
settings = GenerateSettings.from_config(params.settings)
# the ridge V->T generator learns from the rows the diffusion generator learnt from
job = GeneratorJob.read(snakemake, cv_repeats=settings.cv_repeats)
for spec in job.targets:
    logger.info(
        "%s (%s): %d train/val, %d test rows",
        spec.name,
        spec.settings.kind,
        spec.rows.n_train,
        spec.rows.n_test,
    )


t_gen = {
    tuple(cell): edges.read_vector_map(path, "t_gen")
    for cell, path in zip(params.cells, snakemake.input.t_gen, strict=True)
}
with threadpool_limits(snakemake.threads):
    summary, perms = evaluate_generator(
        job.targets,
        **job.keywords(),
        t_gen=t_gen,
        permutations=settings.permutations,
        reference=tuple(params.reference),
        labels=corpus_labels(params.corpus),
        family=params.family,
        progress=logger.info,
    )
edges.write(snakemake.output.rows, summary, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.permutations, perms, key="row_id", producer=snakemake.rule)
logger.info("%d summary rows, %d permutation draws", len(summary), len(perms))
