"""Points of a probe knob: the Monte Carlo spread across replicate seeds against the seconds of
one probe job at that setting (rule cost_probe_points)."""

import pandas as pd

from tacgen_lib.cost.benchmarks import read_benchmark
from tacgen_lib.cost.points import write_points
from tacgen_lib.cost.spread import replicate_seconds
from tacgen_lib.cost.sweeps import Seconds, bootstrap_spread_points, permutation_points
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
knob = snakemake.wildcards.knob
reps = pd.concat([edges.read(p).frame for p in snakemake.input.rows], ignore_index=True)
benches = {}
for (label, _rep), bench in zip(snakemake.params.cells, snakemake.input.benchmarks, strict=True):
    benches.setdefault(label, []).append(read_benchmark(bench))
seconds = {k: Seconds(*replicate_seconds(v)) for k, v in benches.items()}
build = {"probe_bootstrap": bootstrap_spread_points, "probe_permutations": permutation_points}
table = build[knob](knob, reps, seconds, snakemake.params.default)
table = write_points(table, snakemake.output.points, snakemake.output.points)
for r in table.itertuples(index=False):
    logger.info("%s = %s: %s %.4g [%.4g, %.4g] in %.1f s (%d jobs)", r.knob, r.label, r.metric,
                r.value, r.ci_low, r.ci_high, r.wall_s, r.n_jobs)  # fmt: skip
