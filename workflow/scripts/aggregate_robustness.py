"""Robustness of the headline probes: protocol variants, multiple comparisons, the training-size
sweep and the within-scale split (rule aggregate_robustness)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.io import edges, log
from tacgen_lib.probes.multiplicity import ci_counts
from tacgen_lib.probes.protocol import tidy
from tacgen_lib.probes.robustness import RobustnessSettings
from tacgen_lib.report import robustness as report
from tacgen_lib.report.write import write_figure, write_table

logger = log.for_rule(snakemake)
robust = RobustnessSettings.from_config(snakemake.params.robustness, snakemake.params.families)
summary = tidy(edges.read(snakemake.input.summary).frame)
null_families = sorted(set(summary.loc[summary["null_corpus"].astype(bool), "family"]))


def gather(paths, key="row_id"):
    frames = [edges.read(p).frame for p in paths]
    return (
        pd.concat(frames, ignore_index=True).sort_values(key, ignore_index=True)
        if frames
        else pd.DataFrame({key: pd.Series([], dtype=str)})
    )


size = gather(snakemake.input.training_size)
within = gather(snakemake.input.within_scale)
long = report.headline_long(summary, robust.families, robust.protocols)
counts = ci_counts(summary)
counts.insert(0, "row_id", counts["protocol"] + "|" + counts["family"])
edges.write(snakemake.output.robustness, long, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.training_size, size, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.within_scale, within, key="row_id", producer=snakemake.rule)
edges.write(snakemake.output.multiplicity, counts, key="row_id", producer=snakemake.rule)

table = report.robustness_table(long, robust.families, robust.protocols)
sentence = report.survival_sentence(table, null_families)
logger.info("%s", sentence)
write_table(
    table,
    snakemake.output.robustness_html,
    title="Headline probes under each protocol variant: Δ [95% fixed-test bootstrap CI]. "
    + sentence,
    mono=(),
)
write_table(
    report.multiplicity_table(counts),
    snakemake.output.multiplicity_html,
    title="Multiple comparisons: CIs excluding 0 against chance, Holm and Benjamini–Hochberg "
    "(one-sided bootstrap p of Δ ≤ 0, adjusted within each protocol)",
    mono=(),
)
write_table(
    report.within_scale_table(long, within),
    snakemake.output.within_scale_html,
    title="Held-out scale vs a random within-scale split of the training rows (raw V vs V+T, concat)",
    mono=(),
)
write_table(
    report.training_size_table(size),
    snakemake.output.training_size_html,
    title="Probe-side training-size sweep: Δ [95% CI] on nested training subsets",
    mono=(),
)
write_figure(report.training_size_figure(size), snakemake.output.training_size_png)
for _, r in counts.iterrows():
    logger.info(
        "%s %s: %d comparisons, %d CIs exclude 0 (%.1f by chance), Holm %d, BH %d",
        r["protocol"],
        r["family"],
        r["comparisons"],
        r["ci_excludes_0"],
        r["expected_by_chance"],
        r["holm_rejections"],
        r["bh_rejections"],
    )
