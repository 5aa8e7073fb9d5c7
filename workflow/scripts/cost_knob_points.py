"""Points of one swept knob from the main-rule edges of each of its settings and the benchmark
files of their jobs (rule cost_knob_points; the reader: tacgen_lib.cost.readers)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.cost.points import log_points, write_points
from tacgen_lib.cost.readers import EDGE_COLUMNS, SettingRun, read_knob
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.benchmarks import read_benchmark

logger = log.for_rule(snakemake)
knob, params = snakemake.wildcards.knob, snakemake.params
runs = []
for p in params.plan:
    runs.append(
        SettingRun(
            label=p["label"],
            number=p["number"],
            is_default=p["is_default"],
            rep=p["rep"],
            edges={
                role: [edges.read(f, columns=EDGE_COLUMNS.get(role)).frame for f in files]
                for role, files in p["edges"].items()
            },
            benchmarks=[read_benchmark(b) for b in p["benchmarks"]],
            options=p["options"],
        )
    )
    logger.info(
        "%s = %s (replicate %d): %d edges, %d jobs",
        knob,
        p["label"],
        p["rep"],
        sum(len(f) for f in p["edges"].values()),
        len(p["benchmarks"]),
    )
table = write_points(
    read_knob(knob, params.reads, runs, params.options),
    snakemake.output.points,
    snakemake.output.points,
)
log_points(table, logger.info)
