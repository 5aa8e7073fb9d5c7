"""V vs V+T (concat) of every probe family on one backbone family's features, under the linear
and the 2-layer protocol (rule family_probe)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.keys import corpus_labels
from tacgen_lib.io import edges, log
from tacgen_lib.probes.backbone_families import backbone_family_rows
from tacgen_lib.probes.rows import trainable_family_rows
from tacgen_lib.probes.settings import ProbeFamily

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
    probe_family = ProbeFamily.from_config(probe, spec)
    corpus = probe_family.corpus
    rows = trainable_family_rows(
        manifest, splits, probe_family, corpora[corpus], rule=snakemake.rule
    )
    logger.info(
        "%s on %s: %d train/val rows, %d test rows", probe, corpus, rows.n_train, rows.n_test
    )
    with threadpool_limits(snakemake.threads):
        frames.append(
            backbone_family_rows(
                family,
                probe,
                rows,
                vision=rows.read_block(vision[corpus], "vit"),
                tactile=rows.read_block(tactile[corpus], "vit"),
                probes_cfg=snakemake.params.settings,
                kind=probe_family.kind,
                protocols=snakemake.params.protocols,
                seed=int(snakemake.params.seed),
                labels=labels,
                null_corpus=corpus_labels(corpora[corpus])["null_corpus"],
                progress=logger.info,
            )
        )
edges.write(
    snakemake.output.rows,
    pd.concat(frames, ignore_index=True),
    key="row_id",
    producer=snakemake.rule,
)
