"""Points of a policy knob (width, epochs of the V-only policy) from the policy summary and the
train_policy + rollout_policy benchmark files (rule cost_policy_points)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.cost.points import log_points, write_points
from tacgen_lib.cost.spread import replicate_seconds
from tacgen_lib.cost.sweeps import Seconds, policy_points
from tacgen_lib.io import log
from tacgen_lib.runtime.benchmarks import Benchmark, read_benchmark

logger = log.for_rule(snakemake)
params = snakemake.params
summary = pd.read_parquet(snakemake.input.summary)
cells = {(int(h), int(e)): (label, setting) for label, setting, h, e in params.cells}
rows = summary[summary["condition"] == "v"]
keys = [(int(h), int(e)) for h, e in zip(rows["hidden"], rows["epochs"], strict=True)]
rows = rows[[k in cells for k in keys]]
keys = [k for k in keys if k in cells]
rows = rows.assign(label=[cells[k][0] for k in keys], setting=[cells[k][1] for k in keys])
# One run of a setting = its training job + its rollout shards (summed), mean over seeds.
jobs = {}
for (label, seed), bench in zip(params.bench_cells, snakemake.input.benchmarks, strict=True):
    jobs.setdefault((label, seed), []).append(read_benchmark(bench))
per_seed = {}
for (label, _seed), bs in jobs.items():
    b = Benchmark(sum(x.wall for x in bs), sum(x.cpu for x in bs), max(x.max_rss_mb for x in bs))
    per_seed.setdefault(label, []).append((b, len(bs)))
seconds = {
    k: Seconds(*replicate_seconds([b for b, _ in v])[:2], sum(n for _, n in v))
    for k, v in per_seed.items()
}
table = policy_points(snakemake.wildcards.knob, rows, seconds, params.default)
table = write_points(table, snakemake.output.points, snakemake.output.points)
log_points(table, logger.info)
