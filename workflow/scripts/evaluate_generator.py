"""Probe V+T_gen (and its controls) for every cell of one generator against the corpus's
baselines (rule evaluate_generator)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable, ids_in_split
from tacgen_lib.generate.baselines import baselines_from_frame, target_specs
from tacgen_lib.generate.evaluate import evaluate_generator
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
w, params = snakemake.wildcards, snakemake.params
settings = GenerateSettings.from_config(params.settings)
corpus_cfg = params.corpus
splits = edges.read(snakemake.input.splits).frame
# the ridge V->T generator learns from the rows the diffusion generator learnt from
generator_train_ids = sorted(ids_in_split(splits, "train", w.corpus))
assert_trainable(generator_train_ids, splits, rule=snakemake.rule, allowed=("train",))
targets = target_specs(
    edges.read(snakemake.input.manifest).frame,
    splits,
    corpus=w.corpus,
    targets=params.targets,
    corpus_config=corpus_cfg,
    probes_config=params.probes,
    probe_seed=params.probe_seed,
    rule=snakemake.rule,
    cv_repeats=settings.cv_repeats,
)
for spec in targets:
    logger.info(
        "%s (%s): %d train/val, %d test rows",
        spec.name,
        spec.settings.kind,
        spec.rows.n_train,
        spec.rows.n_test,
    )
baselines = baselines_from_frame(
    edges.read(snakemake.input.baselines).frame, targets, source=snakemake.input.baselines
)


vision = edges.read_vector_map(snakemake.input.v, "vit")
t_real = edges.read_vector_map(snakemake.input.t, "vit")
t_gen = {
    tuple(cell): edges.read_vector_map(path, "t_gen")
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
        baselines=baselines,
        permutations=settings.permutations,
        generator_train_ids=generator_train_ids,
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
