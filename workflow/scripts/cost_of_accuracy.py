"""The cost-of-accuracy page: every knob's points, sentences, Pareto fronts and the marginal
accuracy per extra minute (rule cost_of_accuracy)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from pathlib import Path

import pandas as pd

from tacgen_lib.cost.points import POINT_COLUMNS, read_points
from tacgen_lib.io import log
from tacgen_lib.io.hashed import atomic_write_bytes
from tacgen_lib.report.cost import cost_figures, cost_page_html, knob_sentences, marginal_view
from tacgen_lib.report.write import write_figure, write_table
from tacgen_lib.runtime.benchmarks import cpu_label

logger = log.for_rule(snakemake)
params = snakemake.params
tables = [read_points(p) for p in snakemake.input.points]
points = (
    pd.concat(tables, ignore_index=True)
    if tables
    else pd.DataFrame(columns=[*POINT_COLUMNS, "direction"])
)
swept = list(params.swept)
note = (
    f"Measured on {cpu_label()}; seconds are wall times of one run of a setting from its jobs' "
    "benchmark files, and vary with machine load. "
    + (
        f"Swept knobs (config cost.knobs): {', '.join(swept)}. "
        if swept
        else "This run sweeps no knob: the points below are what the run's own grids vary. "
        "For every knob, run `snakemake --cores 2 cost_of_accuracy --configfile config/cost.yaml`. "
    )
)
sentences = knob_sentences(points) if len(points) else ["No knob has points in this run."]
atomic_write_bytes(
    snakemake.output.html,
    cost_page_html(
        points, sentences, title="Cost of accuracy: what each knob's settings buy", note=note
    ).encode(),
)
write_table(
    marginal_view(points),
    snakemake.output.marginal,
    title="Marginal accuracy per extra minute between consecutive Pareto points",
    mono=(),
)
Path(snakemake.output.figure).mkdir(parents=True, exist_ok=True)
for knob, fig in cost_figures(points, params.stages).items():
    write_figure(fig, f"{snakemake.output.figure}/{knob}.png")
points.to_csv(snakemake.output.tsv, sep="\t", index=False)
for s in sentences:
    logger.info("%s", s)
