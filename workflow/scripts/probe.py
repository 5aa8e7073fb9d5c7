"""One probe family under one protocol variant at one probe seed: V vs V+T on raw and aligned
features (rule probe)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.io import edges, log
from tacgen_lib.probes.protocol import run_family
from tacgen_lib.probes.rows import family_rows, strata_for
from tacgen_lib.probes.settings import ProbeSettings

logger = log.for_rule(snakemake)
family = snakemake.params.family
corpus = snakemake.params.corpus
settings = ProbeSettings.from_config(
    snakemake.params.settings,
    family["kind"],
    int(snakemake.wildcards.seed),
    protocol=snakemake.wildcards.protocol,
)
run = snakemake.params.run  # the protocol variant's budget: headline only? controls?
heads_variant = snakemake.params.heads_variant
manifest = edges.read(snakemake.input.manifest).frame
splits = edges.read(snakemake.input.splits).frame
rows = family_rows(
    manifest,
    splits,
    corpus=family["corpus"],
    target=family["target"],
    kind=family["kind"],
    strata=strata_for(corpus),
)
# The probes train on train + val rows (no early stopping); test rows only score them.
assert_trainable(rows.train_ids, splits, rule=snakemake.rule, allowed=("train", "val"))
logger.info(
    "%s (protocol %s): %s probe of %s on %s: %d train/val rows, %d test rows (%d unlabelled "
    "dropped); headline only: %s, controls: %s",
    family["name"],
    settings.protocol,
    family["kind"],
    family["target"],
    family["corpus"],
    rows.n_train,
    rows.n_test,
    rows.n_unlabelled,
    run["headline_only"],
    run["controls"],
)


vision = rows.train_test(
    edges.read(snakemake.input.vision, require={family["vision"]: "vector"}), family["vision"]
)
tactile = {
    variant: rows.train_test(edges.read(path, require={"vit": "vector"}), "vit")
    for variant, path in zip(snakemake.params.variants, snakemake.input.tactile, strict=True)
}
aligned = {}
for seed, path in zip(snakemake.params.align_seeds, snakemake.input.aligned, strict=True):
    edge = edges.read(path, require={"v_aligned": "vector", "t_aligned": "vector"})
    aligned[int(seed)] = (*rows.train_test(edge, "v_aligned"), *rows.train_test(edge, "t_aligned"))

with threadpool_limits(snakemake.threads):
    result = run_family(
        family["name"],
        rows,
        vision=vision,
        tactile=tactile,
        aligned=aligned,
        fusions=snakemake.params.fusions,
        heads_variant=heads_variant,
        settings=settings,
        labels={
            "vision": family["vision"],
            "heads_from": family["heads_from"],
            "design": corpus.get("design", corpus["kind"]),
            "null_corpus": bool(corpus.get("null", False)),
        },
        progress=logger.info,
        headline_only=run["headline_only"],
        controls=run["controls"],
    )
edges.write(snakemake.output.rows, result.rows, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.sweep, result.sweep, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.confusion, result.confusion, key="row_id", producer=snakemake.rule)
main = result.rows.loc[result.rows["control"] == "none", "status"].value_counts().to_dict()
logger.info("%d result rows (comparisons by status: %s)", len(result.rows), main)
