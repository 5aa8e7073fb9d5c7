"""Generation summary (evaluations ⋈ benchmark wall times) and the Generation report (rule aggregate_generate)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import io

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from tacgen_lib.corpus.splits import ids_in_split
from tacgen_lib.io import edges, hashed, log
from tacgen_lib.report import generate as gen_report
from tacgen_lib.report.generate_family import family_table
from tacgen_lib.report.write import write_figure, write_table
from tacgen_lib.runtime.benchmarks import benchmark_seconds

logger = log.for_rule(snakemake)
inp, out, params = snakemake.input, snakemake.output, snakemake.params
ref = params.ref

rows = pd.concat(
    [edges.read(p, require={"row_id": "str", "delta": "float"}).frame for p in inp.rows],
    ignore_index=True,
)
perms = pd.concat([edges.read(p).frame for p in inp.permutations], ignore_index=True)
curves = pd.concat([edges.read(p).frame for p in inp.curves], ignore_index=True)
sample_seconds = {
    (c, int(s), sampler, float(g), int(st)): benchmark_seconds(path)
    for (c, s, sampler, g, st), path in zip(params.sample_cells, inp.sample_bench, strict=True)
}
train_seconds = {
    (c, int(s)): benchmark_seconds(path)
    for (c, s), path in zip(params.generators, inp.train_bench, strict=True)
}
# All evaluation rows as one hashed edge (reproducible: no wall times) ...
edges.write(out.evaluation, rows.sort_values("row_id"), key="row_id", producer=snakemake.rule)
# ... and the summary with wall times: a report table, not an edge (wall times vary by run).
summary = gen_report.generation_summary(rows, sample_seconds, train_seconds)
sink = io.BytesIO()
pq.write_table(pa.Table.from_pandas(summary, preserve_index=False), sink, compression="zstd")
hashed.atomic_write_bytes(out.summary, sink.getvalue())

label = f"{ref['sampler']} {ref['steps']} steps, w = {ref['guidance']}"
write_table(
    gen_report.headline_table(summary, ref),
    out.headline,
    title=f"Generated vs real touch in the probes ({label}; Δ against linear V on the test split)",
    mono=(),
)
write_table(
    gen_report.honesty_table(summary, ref),
    out.honesty,
    title=f"Where generated touch must not help ({label})",
    mono=(),
)
write_table(
    family_table(summary),
    out.family,
    title="Every generated-touch row of a corpus and target, read as one family",
    mono=(),
    notes=[
        "Family-wise intervals: Bonferroni over the rows compared per corpus and target (V + "
        "T_gen and its shuffled control in every sampling cell of every generator seed, and "
        "the ridge V→T generator's two arms per seed), at a family-wise error rate of 5 %; a "
        "95 % CI alone lies above 0 by chance in about one row of twenty."
    ],
)
write_table(
    gen_report.protocol_table(summary, ref),
    out.protocol,
    title=(
        f"The paper's cross-seed protocol ({ref['sampler']} {ref['steps']} steps, Δ_gen averaged "
        "over guidance w > 0 per seed)"
    ),
    mono=(),
    notes=[
        gen_report.paper_protocol_note()
        + " A corpus where appearance carries the label (natural, ρ = 1) is where that pattern "
        "can hold; where it does not (ρ = 0, the paired and null corpora) it must fail.",
        "The interval spans generator seeds only: every seed's cells score the same test rows, "
        "so it leaves out test-row sampling, and an interval above 0 is not a gain (read the "
        "null corpus's rows). The fixed-test bootstrap CIs of the other tables include it.",
    ],
)
write_table(
    gen_report.fidelity_table(summary),
    out.fidelity,
    title="Generated vs real test latents per sampling cell",
    mono=(),
)
write_figure(gen_report.guidance_seed_figure(summary, ref["sampler"], ref["steps"]), out.heatmap)
write_figure(gen_report.steps_seconds_figure(summary), out.steps)
write_figure(gen_report.permutation_figure(perms, ref), out.permutation)
write_figure(gen_report.curve_figure(curves), out.curves)

# PCA of real vs generated test latents of the reference cell (first corpus, first seed).
splits = edges.read(inp.splits).frame
test_ids = sorted(ids_in_split(splits, "test", params.pca_corpus))
real = edges.read(inp.pca_real, columns=["vit"]).subset(test_ids).vectors["vit"]
gen = edges.read(inp.pca_gen, columns=["t_gen"]).subset(test_ids).vectors["t_gen"]
write_figure(
    gen_report.pca_figure(
        real, gen, title=f"{params.pca_corpus} test rows, seed {params.pca_seed}, {label}"
    ),
    out.pca,
)
logger.info(
    "%d evaluation rows, %d generators, %d sampling cells; mean Δ_gen %.3f",
    len(rows),
    len(train_seconds),
    len(sample_seconds),
    float(np.nanmean(rows.loc[rows["input"] == "t_gen", "delta"])),
)
