"""What V sees: every simulated corpus's visible factors decoded from its vision features by a
linear and a nonlinear probe on every non-test row (rule visibility_check)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.looks import visible_factors
from tacgen_lib.generate.visibility import (
    VisibilityCorpus,
    VisibilitySettings,
    visibility_check,
    visibility_mlp,
    visibility_probe,
)
from tacgen_lib.io import edges, log
from tacgen_lib.report import visibility as report
from tacgen_lib.report.write import write_figure, write_table

logger = log.for_rule(snakemake)
params = snakemake.params
settings = VisibilitySettings.from_config(params.visibility)
splits = edges.read(snakemake.input.splits, require={"split": "str", "corpus": "str"}).frame
manifest = edges.read(snakemake.input.manifest).frame
corpora = []
for corpus, path in zip(params.corpora, snakemake.input.v, strict=True):
    split = splits.loc[splits["corpus"] == corpus].set_index("sample_id")["split"]
    corpora.append(
        VisibilityCorpus(
            corpus,
            edges.read_vector_map(path, "vit"),
            visible_factors(
                manifest.loc[manifest["corpus"] == corpus],
                appearance_class=corpus in params.natural,
            ),
            # the probes fit on every non-test row: never a test row
            train=sorted(split.index[split != "test"]),
            test=sorted(split.index[split == "test"]),
        )
    )
    logger.info("%s: %d train, %d test rows", corpus, len(corpora[-1].train), len(corpora[-1].test))
probe = visibility_probe(params.probes, params.probe_seed, settings)
# the gate's factors are also read by the probes stage's 2-layer probe (its CV grid)
mlp = visibility_mlp(params.probes)
# one BLAS thread in this process or in each of the job's workers (fork_map): the rows do not
# depend on the cores Snakemake gives the job
with threadpool_limits(1):
    rows = visibility_check(
        corpora, probe, settings, mlp=mlp, progress=logger.info, workers=snakemake.threads
    )
edges.write(snakemake.output.edge, rows, key="row_id", producer=snakemake.rule)
write_table(
    report.visibility_table(rows),
    snakemake.output.table,
    title="What V decodes of what each frame shows (every non-test row; test accuracy)",
    mono=(),
    lead=[report.visibility_sentence(rows, c) for c in sorted(rows["corpus"].unique())],
)
write_figure(report.visibility_figure(rows), snakemake.output.figure)
