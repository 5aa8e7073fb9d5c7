"""Captions, the offline text encoder and the tactile adapter of one corpus (train rows), and
forced-choice accuracy of real, generated and shuffled generated touch on its test rows (rule
language_evidence)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable, ids_in_split
from tacgen_lib.io import edges, log
from tacgen_lib.language.adapter import language_evidence

logger = log.for_rule(snakemake)
w, params = snakemake.wildcards, snakemake.params
splits = edges.read(snakemake.input.splits, require={"split": "str", "corpus": "str"}).frame
train_ids = sorted(ids_in_split(splits, ("train", "val"), w.corpus))
test_ids = sorted(ids_in_split(splits, "test", w.corpus))
# captions, encoder and adapter learn from train + val rows only
assert_trainable(train_ids, splits, rule=snakemake.rule, allowed=("train", "val"))


with threadpool_limits(snakemake.threads):
    rows = language_evidence(
        edges.read(snakemake.input.manifest).frame,
        train_ids,
        test_ids,
        edges.read_vector_map(snakemake.input.t, "vit"),
        edges.read_vector_map(snakemake.input.t_gen, "t_gen"),
        corpus=w.corpus,
        bootstrap=int(params.bootstrap),
        seed=int(params.seed),
    )
edges.write(snakemake.output.rows, rows, key="row_id", producer=snakemake.rule)
for r in rows.itertuples():
    logger.info(
        "%s %s: accuracy %.3f [%.3f, %.3f], vs shuffled %+.3f [%+.3f, %+.3f]",
        r.attribute,
        r.input,
        r.accuracy,
        r.ci_low,
        r.ci_high,
        r.margin_vs_shuffled,
        r.ci_low_vs_shuffled,
        r.ci_high_vs_shuffled,
    )
