"""Points of an alignment knob: retrieval with a bootstrap CI over test rows, against the
seconds of the training jobs (rule cost_align_points)."""

from tacgen_lib.cost.benchmarks import read_benchmark
from tacgen_lib.cost.points import write_points
from tacgen_lib.cost.spread import replicate_seconds
from tacgen_lib.cost.sweeps import Seconds, align_points
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
params = snakemake.params
cells = params.cells  # (value label, seed) in the order of the ranks and benchmark inputs
ranks, benches, n_all, default = {}, {}, None, params.default
for (label, _seed), path, bench in zip(
    cells, snakemake.input.ranks, snakemake.input.benchmarks, strict=True
):
    edge = edges.read(path, require={"rank_v2t": "int"}).frame
    ranks.setdefault(label, []).append(edge["rank_v2t"].to_numpy())
    benches.setdefault(label, []).append(read_benchmark(bench))
    if label == "all":
        n_all = int(edge["n_train_rows"].iloc[0])
    if snakemake.wildcards.knob == "align_steps" and default is None:
        default = str(int(edge["default_steps"].iloc[0]))
seconds = {k: Seconds(*replicate_seconds(v)) for k, v in benches.items()}
table = align_points(
    snakemake.wildcards.knob, ranks, seconds, default, n_resamples=params.bootstrap, seed=0,
    n_all=n_all,
)  # fmt: skip
table = write_points(table, snakemake.output.points, snakemake.output.points)
for r in table.itertuples(index=False):
    logger.info("%s = %s: %s %.3f [%.3f, %.3f] in %.1f s (%d jobs)", r.knob, r.label, r.metric,
                r.value, r.ci_low, r.ci_high, r.wall_s, r.n_jobs)  # fmt: skip
