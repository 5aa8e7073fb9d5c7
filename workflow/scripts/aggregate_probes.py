"""Probe summary over families and seeds, and the probes' report tables and figures
(rule aggregate_probes)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from pathlib import Path

import pandas as pd

from tacgen_lib.io import edges, log
from tacgen_lib.probes.multiplicity import adjust
from tacgen_lib.probes.protocol import tidy
from tacgen_lib.report import probe_figures
from tacgen_lib.report import probes as report_probes
from tacgen_lib.report.write import write_figure, write_table

logger = log.for_rule(snakemake)


def gather(paths):
    frames = [edges.read(p).frame for p in paths]
    frames = [f for f in frames if len(f)] or frames[:1]
    return pd.concat(frames, ignore_index=True).sort_values("row_id", ignore_index=True)


# every protocol variant's rows; p-values adjusted for multiplicity within each protocol
summary = adjust(tidy(gather(snakemake.input.rows)))
sweep = tidy(gather(snakemake.input.sweep))
confusion = tidy(gather(snakemake.input.confusion))
for name, frame in (("summary", summary), ("sweep", sweep), ("confusion", confusion)):
    edges.write(snakemake.output[name], frame, key="row_id", producer=snakemake.rule)
# The probe tables below show the paper's protocol (raw); the variants are on the Robustness page.
summary = summary.loc[summary["protocol"] == "raw"].reset_index(drop=True)
sweep = sweep.loc[sweep["protocol"] == "raw"].reset_index(drop=True)
confusion = confusion.loc[confusion["protocol"] == "raw"].reset_index(drop=True)

tables = {
    "controlled": (
        report_probes.controlled_table(summary),
        "Probes on the appearance-controlled corpus (pixel-V headline, ViT-V sensitivity)",
    ),
    "paired": (
        report_probes.paired_table(summary),
        "Probes on the paired corpus, with the null corpus beside",
    ),
    "sweep_html": (
        report_probes.sweep_table(sweep, summary),
        "Δ across the regulariser grid for every fusion variant (* = chosen by CV for V+T)",
    ),
    "align_seeds": (
        report_probes.align_seed_table(summary),
        "Aligned-feature probes over alignment seeds (mean ± sd)",
    ),
    "variants": (
        report_probes.variant_table(summary),
        "Tactile preprocessing variants: raw V + raw T (concat)",
    ),
    "controls": (
        report_probes.controls_table(summary),
        "Controls: Δ under broken pairings, permuted labels, random features, resampled training rows",
    ),
    "fusions": (report_probes.fusions_frame(), "Fusion variants of V and T features"),
}
notes = {
    "controlled": report_probes.skipped_note(summary, controlled=True),
    "paired": report_probes.skipped_note(summary, controlled=False),
}
lead = {}
for name in ("controlled", "paired"):
    table, title = tables[name]
    table, lead[name], marks = report_probes.comparison_page(table)
    tables[name], notes[name] = (table, title), [*notes[name], *marks]
for name, (table, title) in tables.items():
    write_table(
        table,
        snakemake.output[name],
        title=title,
        mono=(),
        notes=notes.get(name, ()),
        lead=lead.get(name, ()),
    )
    logger.info("table %s: %d rows", name, len(table))
# one figure per family: forest plots and confusion matrices (report directories)
Path(snakemake.output.forest).mkdir(parents=True, exist_ok=True)
for fam in probe_figures.forest_families(summary):
    write_figure(probe_figures.forest_plot(summary, fam), f"{snakemake.output.forest}/{fam}.png")
Path(snakemake.output.confusion_png).mkdir(parents=True, exist_ok=True)
for fam, fig in probe_figures.confusion_figures(confusion).items():
    write_figure(fig, f"{snakemake.output.confusion_png}/{fam}.png")
main = summary.loc[summary["control"] == "none"]
logger.info(
    "%d raw-protocol summary rows; %d comparisons (%s); criterion met in %d of %d evaluated "
    "(%d with Holm-adjusted p)",
    len(summary),
    len(main),
    main["status"].value_counts().to_dict(),
    int(main["criterion_met"].fillna(False).astype(bool).sum()),
    int(main["criterion_met"].notna().sum()),
    int(main["criterion_adjusted"].fillna(False).astype(bool).sum()),
)
