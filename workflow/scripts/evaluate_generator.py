"""Probe V vs V+T_real vs V+T_gen (and controls) for every cell of one generator (rule evaluate_generator)."""

from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.generate.evaluate import TargetSpec, evaluate_generator
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.io import edges, log
from tacgen_lib.probes.protocol import ProbeSettings, family_rows, strata_for

logger = log.for_rule(snakemake)
w, params = snakemake.wildcards, snakemake.params
settings = GenerateSettings.from_config(params.settings)
corpus_cfg = params.corpus
manifest = edges.read(snakemake.input.manifest).frame
splits = edges.read(snakemake.input.splits).frame
targets = []
for target, kind in params.targets.items():
    rows = family_rows(
        manifest, splits, corpus=w.corpus, target=target, kind=kind,
        strata=strata_for(corpus_cfg),
    )  # fmt: skip
    # The probes train on train + val rows (as in the probes stage); test rows only score.
    assert_trainable(rows.train_ids, splits, rule=snakemake.rule, allowed=("train", "val"))
    probe_settings = ProbeSettings.from_config(params.probes, kind, params.probe_seed)
    targets.append(TargetSpec(target, rows, probe_settings))
    logger.info("%s (%s): %d train/val, %d test rows", target, kind, rows.n_train, rows.n_test)


def vectors(path, column):
    edge = edges.read(path, columns=[column], require={column: "vector"})
    return dict(zip(edge.ids, edge.vectors[column], strict=True))


vision = vectors(snakemake.input.v, "vit")
t_real = vectors(snakemake.input.t, "vit")
t_gen = {
    tuple(cell): vectors(path, "t_gen")
    for cell, path in zip(params.cells, snakemake.input.t_gen, strict=True)
}
with threadpool_limits(snakemake.threads):
    summary, perms = evaluate_generator(
        targets,
        corpus=w.corpus,
        seed=int(w.seed),
        vision=vision,
        t_real=t_real,
        t_gen=t_gen,
        permutations=settings.permutations,
        gammas=settings.nonlinear_gammas,
        reference=tuple(params.reference),
        labels={
            "design": corpus_cfg.get("design", corpus_cfg["kind"]),
            "null_corpus": bool(corpus_cfg.get("null", False)),
        },
        progress=logger.info,
    )
edges.write(snakemake.output.rows, summary, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.permutations, perms, key="row_id", producer=snakemake.rule)
logger.info("%d summary rows, %d permutation draws", len(summary), len(perms))
