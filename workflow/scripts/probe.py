"""One probe family under one protocol variant at one probe seed: V vs V+T on raw and aligned
features (rule probe)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.keys import corpus_labels
from tacgen_lib.io import edges, log
from tacgen_lib.probes.family_job import FamilyJob
from tacgen_lib.probes.protocol import run_family
from tacgen_lib.probes.settings import ProbeSettings

logger = log.for_rule(snakemake)
w, params = snakemake.wildcards, snakemake.params
# The probes train on train + val rows (no early stopping); test rows only score them.
job = FamilyJob.read(snakemake)
family, rows = job.family, job.rows
settings = ProbeSettings.from_config(params.settings, family.kind, int(w.seed), protocol=w.protocol)
# the protocol variant's budget: headline comparisons only? controls?
headline_only, controls = params.headline_only, params.controls
logger.info(
    "%s (protocol %s): %s probe of %s on %s: %d train/val rows, %d test rows (%d unlabelled "
    "dropped); headline only: %s, controls: %s",
    family.name,
    settings.protocol,
    family.kind,
    family.target,
    family.corpus,
    rows.n_train,
    rows.n_test,
    rows.n_unlabelled,
    headline_only,
    controls,
)


aligned = {}
for seed, path in zip(params.align_seeds, snakemake.input.aligned, strict=True):
    edge = edges.read(path, require={"v_aligned": "vector", "t_aligned": "vector"})
    aligned[int(seed)] = (*rows.train_test(edge, "v_aligned"), *rows.train_test(edge, "t_aligned"))

with threadpool_limits(snakemake.threads):
    result = run_family(
        family.name,
        rows,
        vision=job.vision(snakemake.input.vision),
        tactile=job.tactile(params.variants, snakemake.input.tactile),
        aligned=aligned,
        fusions=params.fusions,
        heads_variant=params.heads_variant,
        settings=settings,
        labels={
            "vision": family.vision,
            "heads_from": family.heads_from,
            **corpus_labels(params.corpus),
        },
        progress=logger.info,
        headline_only=headline_only,
        controls=controls,
    )
edges.write(snakemake.output.rows, result.rows, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.sweep, result.sweep, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.confusion, result.confusion, key="row_id", producer=snakemake.rule)
main = result.rows.loc[result.rows["control"] == "none", "status"].value_counts().to_dict()
logger.info("%d result rows (comparisons by status: %s)", len(result.rows), main)
