"""Summary, paired deltas, sweep and failure modes of the policy stage; its report items
(rule aggregate_policy)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from collections import defaultdict
from pathlib import Path

import pandas as pd

from tacgen_lib.io import edges, log
from tacgen_lib.policy import summary as policy_summary
from tacgen_lib.policy.palpation import frame_names
from tacgen_lib.policy.policy_cells import all_cells, cell_name, main_cells
from tacgen_lib.policy.settings import PolicySettings
from tacgen_lib.report import policy as report_policy
from tacgen_lib.report.write import write_figure, write_table
from tacgen_lib.runtime.benchmarks import benchmark_seconds

logger = log.for_rule(snakemake)
settings = PolicySettings.from_config(snakemake.params.settings)
cells = all_cells(settings)
if [cell_name(c) for c in cells] != list(snakemake.params.cells):
    raise ValueError("rule aggregate_policy: the cells of the rule and of the settings differ")
parts, seconds = defaultdict(list), defaultdict(float)
prefix = "results/policy/rollouts/"
for path, bench in zip(snakemake.input.rollouts, snakemake.input.benchmarks, strict=True):
    name = (
        str(Path(path).parent)[len(prefix) :] if path.startswith(prefix) else str(Path(path).parent)
    )
    parts[name].append(edges.read(path).frame)
    seconds[name] += benchmark_seconds(bench)
rollouts = {k: pd.concat(v, ignore_index=True) for k, v in parts.items()}
summary = policy_summary.summarise(rollouts, cells, settings)
deltas = policy_summary.deltas(rollouts, settings)
sweep = policy_summary.sweep(summary, settings)
failures = summary[["cell", "condition", "n_episodes", "slip", "crush", "drop", "miss"]]
edges.write(snakemake.output.summary, summary, key="cell", producer=snakemake.rule)
edges.write(snakemake.output.deltas, deltas, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.sweep, sweep, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.failures, failures, key="cell", producer=snakemake.rule)

main = [cell_name(c) for c in main_cells(settings)]
write_table(
    report_policy.success_table(summary, deltas, main),
    snakemake.output.success,
    title="Held-out success per condition (matched capacity) and Δ vs V-only",
    mono=("cell",),
)
write_table(
    sweep,
    snakemake.output.sweep_table,
    title="V-only capacity sweep",
    mono=(),
    missing="one seed per cell: no spread over seeds",
    notes=report_policy.sweep_notes(summary, sweep),
)
regression = edges.read(snakemake.input.regression).frame
write_table(
    regression,
    snakemake.output.regression_table,
    title="Palpation grip-force regression: ridge V vs V+T-aligned -> log required force",
    mono=(),
)
write_figure(report_policy.sweep_figure(sweep), snakemake.output.sweep_figure)
write_figure(report_policy.failure_figure(summary, main), snakemake.output.failures_figure)
heldout = pd.concat([edges.read(p).frame for p in snakemake.input.heldout], ignore_index=True)
strip = {cell_name(c).split("/")[0]: rollouts[cell_name(c)] for c in main_cells(settings)}
names = frame_names(len(settings.palpation_forces))
write_figure(
    report_policy.filmstrip(heldout, strip, [n for n in names if "left" in n]),
    snakemake.output.filmstrip,
)
collect = sum(benchmark_seconds(p) for p in snakemake.input.collect)
# wall times (benchmark files) go only into this report table, never into a hashed edge
# one run of a cell = its training job + its rollout shards (as the cost page counts it)
train = {
    str(Path(b).relative_to("results/benchmarks/train_policy").with_suffix("")): benchmark_seconds(
        b
    )
    for b in snakemake.input.train_benchmarks
}
cost = summary[["cell", "n_episodes", "success"]].copy()
cost["training s"] = [train.get(c, 0.0) for c in cost["cell"]]
cost["rollout s"] = [seconds[c] for c in cost["cell"]]
cost["total s"] = cost["training s"] + cost["rollout s"]
cost["episodes per rollout s"] = cost["n_episodes"] / cost["rollout s"]
cost.loc[len(cost)] = ["collect_demos (all shards)", len(heldout), None, None, None, collect, None]
write_table(
    cost,
    snakemake.output.cost,
    title="Policy: cost per cell (training + rollouts, as on the cost page)",
    mono=("cell",),
    missing="the episode collection is not a policy cell: it has no success, training or rollout",
)
for r in summary.itertuples():
    logger.info("%-40s success %.3f [%.3f, %.3f]", r.cell, r.success, r.ci_low, r.ci_high)
for r in deltas.itertuples():
    logger.info("Δ %-38s %+.3f [%+.3f, %+.3f]", r.row_id, r.delta, r.ci_low, r.ci_high)
