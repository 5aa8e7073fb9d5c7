"""Whether V decodes the appearance class of the natural design: the linear and the nonlinear V
probe fitted on the labelled and pool rows of one corpus x seed, scored on its test split
(rule regime_appearance; once per run, the class -> frame process being the same at every
rho)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.generate.regime import (
    RegimeSettings,
    appearance_check,
    job_regime_sets,
)
from tacgen_lib.io import edges, log
from tacgen_lib.probes.settings import ProbeSettings

logger = log.for_rule(snakemake)
params = snakemake.params
regime = RegimeSettings.from_config(params.regime)
seed = int(params.seed)
splits = edges.read(snakemake.input.splits, require={"split": "str", "corpus": "str"}).frame
manifest = edges.read(snakemake.input.manifest).frame
# the check's probes fit on labelled and pool rows: never a test row
sets = job_regime_sets(splits, params.corpus, regime, seed, rule=snakemake.rule)
logger.info(
    "%s seed %d: appearance class from V on %d labelled + pool rows, %d test rows",
    params.corpus,
    seed,
    len(sets.labelled) + len(sets.pool),
    len(sets.test),
)
# one BLAS thread in this process or in each of the job's workers (fork_map): the rows do
# not depend on the cores Snakemake gives the job
with threadpool_limits(1):
    appearance = appearance_check(
        edges.read_vector_map(snakemake.input.v, "vit"),
        manifest.set_index("sample_id")["appearance_id"],
        sets,
        ProbeSettings.from_config(params.probes, "logistic", params.probe_seed),
        corpus=params.corpus,
        rho=float(params.rho),
        seed=seed,
        gammas=regime.appearance_gammas,
        bootstrap=regime.bootstrap,
        progress=logger.info,
        workers=snakemake.threads,
    )
edges.write(snakemake.output[0], appearance, key="row_id", producer=snakemake.rule)
logger.info("appearance class from V: %s", appearance["score"].round(3).tolist())
