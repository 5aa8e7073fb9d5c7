"""V vs V+T (concat) of every probe family on one backbone family's features, under the linear
and the 2-layer protocol (rule family_probe)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.io import edges, log
from tacgen_lib.probes.backbone_families import backbone_family_rows
from tacgen_lib.probes.rows import family_rows, strata_for

logger = log.for_rule(snakemake)
family = snakemake.wildcards.family
corpora, labels = snakemake.params.corpora, snakemake.params.labels
manifest = edges.read(snakemake.input.manifest).frame
splits = edges.read(snakemake.input.splits).frame
# every feature edge keeps its backbone's features in column "vit", whatever the family
vision = dict(zip(corpora, snakemake.input.vision, strict=True))
tactile = dict(zip(corpora, snakemake.input.tactile, strict=True))
logger.info("%s: V %s, T %s", family, labels["vision"], labels["tactile"])
frames = []
for probe, spec in snakemake.params.probes.items():
    corpus = spec["corpus"]
    rows = family_rows(
        manifest,
        splits,
        corpus=corpus,
        target=spec["target"],
        kind=spec["kind"],
        strata=strata_for(corpora[corpus]),
    )
    assert_trainable(rows.train_ids, splits, rule=snakemake.rule, allowed=("train", "val"))
    logger.info(
        "%s on %s: %d train/val rows, %d test rows", probe, corpus, rows.n_train, rows.n_test
    )
    with threadpool_limits(snakemake.threads):
        frames.append(
            backbone_family_rows(
                family,
                probe,
                rows,
                vision=rows.train_test(
                    edges.read(vision[corpus], require={"vit": "vector"}), "vit"
                ),
                tactile=rows.train_test(
                    edges.read(tactile[corpus], require={"vit": "vector"}), "vit"
                ),
                probes_cfg=snakemake.params.settings,
                kind=spec["kind"],
                protocols=snakemake.params.protocols,
                seed=int(snakemake.params.seed),
                labels=labels,
                null_corpus=bool(corpora[corpus].get("null", False)),
                progress=logger.info,
            )
        )
edges.write(
    snakemake.output.rows,
    pd.concat(frames, ignore_index=True),
    key="row_id",
    producer=snakemake.rule,
)
