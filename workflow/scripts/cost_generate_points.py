"""Points of a generator knob (sampling steps, sampler) from the generation summary and the
sample_generator benchmark files (rule cost_generate_points)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.cost.points import log_points, write_points
from tacgen_lib.cost.spread import replicate_seconds
from tacgen_lib.cost.sweeps import Seconds, generate_points
from tacgen_lib.io import log
from tacgen_lib.runtime.benchmarks import read_benchmark

logger = log.for_rule(snakemake)
params = snakemake.params
summary = pd.read_parquet(snakemake.input.summary)
cells = {(s, int(st)): (label, setting) for label, setting, s, st in params.cells}
rows = summary[
    (summary["input"] == "t_gen")
    & (summary["corpus"] == params.corpus)
    & (summary["target"] == params.target)
    & (summary["guidance"].astype(float) == float(params.guidance))
]
rows = rows[[(s, int(st)) in cells for s, st in zip(rows["sampler"], rows["steps"], strict=True)]]
rows = rows.assign(
    label=[cells[(s, int(st))][0] for s, st in zip(rows["sampler"], rows["steps"], strict=True)],
    setting=[cells[(s, int(st))][1] for s, st in zip(rows["sampler"], rows["steps"], strict=True)],
)
if rows.empty:
    raise ValueError(
        f"{snakemake.input.summary}: no t_gen rows for corpus {params.corpus!r}, target "
        f"{params.target!r}, guidance {params.guidance} (rule {snakemake.rule})"
    )
benches = {}
for (label, _seed), bench in zip(params.bench_cells, snakemake.input.benchmarks, strict=True):
    benches.setdefault(label, []).append(read_benchmark(bench))
seconds = {k: Seconds(*replicate_seconds(v)) for k, v in benches.items()}
table = generate_points(
    snakemake.wildcards.knob, rows, seconds, params.default, target=params.target
)
table = write_points(table, snakemake.output.points, snakemake.output.points)
log_points(table, logger.info)
