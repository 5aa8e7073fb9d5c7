"""The regime's summary (every corpus x seed x arm) and the report page Where generated touch
helps (rule aggregate_regime)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.generate.regime import SUMMARY_COLUMNS
from tacgen_lib.io import edges, log
from tacgen_lib.report import regime as report
from tacgen_lib.report.write import write_figure, write_table

logger = log.for_rule(snakemake)
inp, out = snakemake.input, snakemake.output


def frames(paths, **kw):
    return pd.concat([edges.read(p, **kw).frame for p in paths], ignore_index=True)


rows = frames(inp.rows, require={"row_id": "str", "score": "float"})
appearance = edges.read(inp.appearance).frame
curves = frames(inp.curves)
summary = rows[list(SUMMARY_COLUMNS)].sort_values("row_id", ignore_index=True)
edges.write(out.evaluation, summary, key="row_id", producer=snakemake.rule)
edges.write(out.summary, summary, key="row_id", producer=snakemake.rule)
view = report.seed_view(summary)
best = curves.groupby(["corpus", "seed", "n_pool", "pairing"])["best_step"].first()
notes = report.findings_notes(view, appearance)
write_table(
    report.findings_table(notes),
    out.findings,
    title="Where generated touch helps: the hypotheses, tested",
    mono=(),
)
write_table(
    report.regime_table(view),
    out.table,
    title="Every arm at the largest pool, the fewest and the most labels (mean over seeds)",
    mono=(),
    notes=[
        "Δ: paired on the same test rows and fixed-test resamples; ↑/↓: seeds whose 95% CI "
        "lies above/below 0. Gap closed = (arm − nonlinear V) / (V + real T − nonlinear V).",
        "Generators' best steps (early stopping on a held-out tenth of the pool): "
        + ", ".join(f"{c} seed {s} N_P={n} {p}: {b}" for (c, s, n, p), b in best.items()),
    ],
)
write_table(
    report.appearance_table(appearance),
    out.appearance,
    title="Is the appearance class decodable from V? (linear vs nonlinear V probe)",
    mono=(),
)
write_figure(report.heatmap_figure(view), out.heatmap)
write_figure(report.curves_figure(view), out.curves)
for note in notes:
    logger.info("%s", note)
