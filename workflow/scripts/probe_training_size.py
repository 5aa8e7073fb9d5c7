"""One family's training-size sweep: raw V vs V+T (concat) on nested training subsets
(rule probe_training_size)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.io import edges, log
from tacgen_lib.probes.robustness import RobustnessSettings, training_size_sweep
from tacgen_lib.probes.rows import family_rows, strata_for
from tacgen_lib.probes.settings import ProbeSettings

logger = log.for_rule(snakemake)
family = snakemake.params.family
corpus = snakemake.params.corpus
robust = RobustnessSettings.from_config(snakemake.params.settings["robustness"])
settings = ProbeSettings.from_config(snakemake.params.settings, family["kind"], 0)
splits = edges.read(snakemake.input.splits).frame
rows = family_rows(
    edges.read(snakemake.input.manifest).frame,
    splits,
    corpus=family["corpus"],
    target=family["target"],
    kind=family["kind"],
    strata=strata_for(corpus),
)
assert_trainable(rows.train_ids, splits, rule=snakemake.rule, allowed=("train", "val"))
logger.info(
    "%s: training sizes %s of %d train/val rows, subset seeds %s, %d test rows",
    family["name"],
    list(robust.size_n_train),
    rows.n_train,
    list(robust.size_seeds),
    rows.n_test,
)


vision = rows.train_test(
    edges.read(snakemake.input.vision, require={family["vision"]: "vector"}), family["vision"]
)
path = dict(zip(snakemake.params.variants, snakemake.input.tactile, strict=True))[
    snakemake.params.heads_variant
]
tactile = rows.train_test(edges.read(path, require={"vit": "vector"}), "vit")
with threadpool_limits(snakemake.threads):
    frame = training_size_sweep(
        family["name"],
        rows,
        vision=vision,
        tactile=tactile,
        settings=settings,
        sizes=robust.size_n_train,
        seeds=robust.size_seeds,
        progress=logger.info,
    )
frame["null_corpus"] = bool(corpus.get("null", False))
edges.write(snakemake.output.rows, frame, key="row_id", producer=snakemake.rule)
logger.info("%d points (%s)", len(frame), frame["status"].value_counts().to_dict())
