"""Points of the backbone-family knob from the families' summary and the benchmark files of
the jobs that made each family's backbones and features (rule cost_backbone_points)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.cost.points import log_points, write_points
from tacgen_lib.cost.sweeps import Seconds, backbone_points
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.benchmarks import read_benchmark

logger = log.for_rule(snakemake)
params = snakemake.params
rows = edges.read(snakemake.input.summary).frame
benches = {}
for family, bench in zip(params.bench_families, snakemake.input.benchmarks, strict=True):
    benches.setdefault(family, []).append(read_benchmark(bench))
# a family's jobs add up (its backbones, its features): one run each, no replicates
seconds = {
    family: Seconds(sum(b.wall for b in runs), sum(b.cpu for b in runs), len(runs))
    for family, runs in benches.items()
}
table = backbone_points(snakemake.wildcards.knob, rows, seconds, params.order, params.default)
table = write_points(table, snakemake.output.points, snakemake.output.points)
log_points(table, logger.info)
