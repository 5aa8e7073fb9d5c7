"""Held-out-scale diagnosis of one family: its headline comparison (raw V vs V+T, concat) on a
random within-scale split of the training rows, under every protocol variant
(rule probe_within_scale)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.io import edges, log
from tacgen_lib.probes.protocol import run_family, tidy
from tacgen_lib.probes.robustness import RobustnessSettings
from tacgen_lib.probes.rows import family_rows, strata_for
from tacgen_lib.probes.settings import ProbeSettings

logger = log.for_rule(snakemake)
family = snakemake.params.family
corpus = snakemake.params.corpus
robust = RobustnessSettings.from_config(snakemake.params.settings["robustness"])
splits = edges.read(snakemake.input.splits).frame
rows = family_rows(
    edges.read(snakemake.input.manifest).frame,
    splits,
    corpus=family["corpus"],
    target=family["target"],
    kind=family["kind"],
    strata=strata_for(corpus),
    within_scale=(robust.within_test_fraction, robust.within_seed),
)
# Only train/val rows are re-split; the corpus's test rows are never read.
assert_trainable(rows.train_ids, splits, rule=snakemake.rule, allowed=("train", "val"))
assert_trainable(rows.test_ids, splits, rule=snakemake.rule, allowed=("train", "val"))
logger.info(
    "%s: within-scale split of the train/val rows: %d train, %d test (fraction %.2f, seed %d)",
    family["name"],
    rows.n_train,
    rows.n_test,
    robust.within_test_fraction,
    robust.within_seed,
)


vision = rows.train_test(
    edges.read(snakemake.input.vision, require={family["vision"]: "vector"}), family["vision"]
)
tactile = {
    variant: rows.train_test(edges.read(path, require={"vit": "vector"}), "vit")
    for variant, path in zip(snakemake.params.variants, snakemake.input.tactile, strict=True)
    if variant == snakemake.params.heads_variant
}
frames = []
with threadpool_limits(snakemake.threads):
    for protocol in robust.protocols:
        result = run_family(
            family["name"],
            rows,
            vision=vision,
            tactile=tactile,
            aligned={},
            fusions=["concat"],
            heads_variant=snakemake.params.heads_variant,
            settings=ProbeSettings.from_config(
                snakemake.params.settings, family["kind"], robust.within_seed, protocol=protocol
            ),
            labels={"split": "within_scale", "null_corpus": bool(corpus.get("null", False))},
            progress=logger.info,
            headline_only=True,
            controls=False,
        )
        frames.append(result.rows)
frame = tidy(pd.concat(frames, ignore_index=True))
edges.write(snakemake.output.rows, frame, key="row_id", producer=snakemake.rule)
logger.info("%d rows", len(frame))
