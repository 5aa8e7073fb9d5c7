"""V alone, V+T_real and the nonlinear V baseline of one corpus's generator targets, once for
every generator seed (rule fit_generator_baselines)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.generate.baselines import baselines_frame, fit_baselines
from tacgen_lib.generate.generator_job import job_target_specs
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
w, params = snakemake.wildcards, snakemake.params
# validated as the generate settings validate them
checked = GenerateSettings(
    nonlinear_gammas=tuple(float(g) for g in params.gammas), cv_repeats=params.cv_repeats
)
gammas = checked.nonlinear_gammas
specs = job_target_specs(
    snakemake, edges.read(snakemake.input.splits).frame, cv_repeats=checked.cv_repeats
)


vision, t_real = (
    edges.read_vector_map(snakemake.input.v, "vit"),
    edges.read_vector_map(snakemake.input.t, "vit"),
)
fits = []
with threadpool_limits(snakemake.threads):
    for spec in specs:
        logger.info(
            "%s (%s): %d train/val, %d test rows; fitting V, V+T_real, nonlinear V",
            spec.name,
            spec.settings.kind,
            spec.rows.n_train,
            spec.rows.n_test,
        )
        fit = fit_baselines(spec, vision, t_real, gammas=gammas)
        fits.append(fit)
        logger.info(
            "%s: regularisers %s, nonlinear gamma %.4g",
            spec.name,
            {k: f"{v:g}" for k, v in fit.reg.items()},
            fit.gamma,
        )
frame = baselines_frame(w.corpus, specs, fits)
edges.write(snakemake.output.baselines, frame, key="row_id", producer=snakemake.rule)
logger.info("%d baseline predictions", len(frame))
