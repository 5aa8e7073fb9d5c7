"""Points of one knob from the edges of each of its setting runs (a swept knob's main-rule
edges, a free knob's stage summary) and the benchmark files of their jobs (rule
cost_knob_points; the reader: tacgen_lib.cost.readers)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from functools import cache

import pandas as pd

from tacgen_lib.cost.points import log_points, write_points
from tacgen_lib.cost.readers import EDGE_COLUMNS, SettingRun, read_knob
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.benchmarks import read_benchmark

logger = log.for_rule(snakemake)
knob, params = snakemake.wildcards.knob, snakemake.params


@cache
def read_edge(path: str, role: str) -> pd.DataFrame:
    return edges.read(path, columns=EDGE_COLUMNS.get(role)).frame


@cache
def read_table(path: str) -> pd.DataFrame:
    return pd.read_parquet(path)  # a stage's summary table: no sidecar


runs = []
for p in params.plan:
    frames = {role: [read_edge(f, role) for f in files] for role, files in p["edges"].items()}
    frames |= {role: [read_table(f) for f in files] for role, files in p["tables"].items()}
    runs.append(
        SettingRun(
            label=p["label"],
            number=p["number"],
            is_default=p["is_default"],
            rep=p["rep"],
            edges=frames,
            benchmarks=[read_benchmark(b) for b in p["benchmarks"]],
            options=p["options"],
        )
    )
    logger.info(
        "%s = %s (replicate %d): %d edges, %d jobs",
        knob,
        p["label"],
        p["rep"],
        sum(len(f) for f in frames.values()),
        len(p["benchmarks"]),
    )
table = write_points(
    read_knob(knob, params.reads, runs, params.options),
    snakemake.output.points,
    snakemake.output.points,
)
log_points(table, logger.info)
