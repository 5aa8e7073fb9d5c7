"""The regime's summary (every corpus x seed x labelled draw x arm) and the report page Where
generated touch helps: the visibility gate, the ladder's verdict, the tables and figures (rule
aggregate_regime)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.generate.regime import SUMMARY_COLUMNS
from tacgen_lib.generate.visibility import visibility_gate
from tacgen_lib.io import edges, log
from tacgen_lib.report import regime as report
from tacgen_lib.report.tables import constants_to_lead
from tacgen_lib.report.write import write_figure, write_table

logger = log.for_rule(snakemake)
inp, out = snakemake.input, snakemake.output


def frames(paths, **kw):
    return pd.concat([edges.read(p, **kw).frame for p in paths], ignore_index=True)


rows = frames(inp.rows, require={"row_id": "str", "score": "float"})
visibility = edges.read(inp.visibility).frame
curves = frames(inp.curves)
summary = rows[list(SUMMARY_COLUMNS)].sort_values("row_id", ignore_index=True)
edges.write(out.evaluation, summary, key="row_id", producer=snakemake.rule)
edges.write(out.summary, summary, key="row_id", producer=snakemake.rule)
# the curve's positive control (rule regime_look_control), where it ran
control = (
    frames(inp.control, require={"row_id": "str", "score": "float"})[list(SUMMARY_COLUMNS)]
    if inp.control
    else pd.DataFrame(columns=list(SUMMARY_COLUMNS))
).sort_values("row_id", ignore_index=True)
edges.write(out.control, control, key="row_id", producer=snakemake.rule)
control_view = report.seed_view(control) if len(control) else None
view = report.seed_view(summary)
best = curves.groupby(["corpus", "seed", "n_pool", "pairing"])["best_step"].first()
# the gate of the regime's corpora: what V decodes of what their frames show, read on the rho
# grid's first corpus (rule visibility_check: the look -> frame process is the same at every rho)
checked = set(visibility["corpus"])
gates = [
    visibility_gate(visibility, c, snakemake.params.gate)
    for c in sorted(view["corpus"].unique())
    if c in checked
]
notes = report.findings_notes(
    view,
    [g.sentence() for g in gates],
    gate_passed=all(g.passed for g in gates),
    control=control_view,
    snr=snakemake.params.look_control_snr,
)
write_table(
    report.findings_table(notes),
    out.findings,
    title="Where generated touch helps: the gate, the ladder's verdict and the hypotheses",
    mono=(),
)
write_table(
    report.ladder_table(view),
    out.ladder,
    title="The generator ladder: from a generator that sees the look to one diffusion sample",
    mono=(),
    notes=[
        "Each rung: a probe (linear) on V + that rung's T_gen, on the same labelled and test "
        "rows; Δ against nonlinear V, paired on the same fixed-test resamples; ↑/↓: replicates "
        "(seed × labelled draw) whose 95% CI lies above/below 0. Headroom captured = (rung − "
        "nonlinear V) / (V ceiling − nonlinear V), given only where that headroom exceeds its "
        "noise (its paired CI above 0, over the replicates and in a replicate); elsewhere "
        "'headroom within noise'. A0 uses the corpus's metadata (the look), "
        "not V: it is the positive control.",
    ],
)
# what every row shares (one pool size by construction, often one target) above the table
arms, shared = constants_to_lead(report.regime_table(view), ("target", "N_P"))
write_table(
    arms,
    out.table,
    title="Every arm at the largest pool, the fewest and the most labels (mean over replicates)",
    mono=(),
    lead=shared,
    notes=[
        "Δ: paired on the same test rows and fixed-test resamples; ↑/↓: replicates (seed × "
        "labelled draw) whose 95% CI lies above/below 0. Gap closed = (arm − nonlinear V) / "
        "(V + real T − nonlinear V); headroom captured = (arm − nonlinear V) / (V ceiling − "
        "nonlinear V), only where that headroom's paired CI lies above 0 ('headroom within "
        "noise' elsewhere). Majority score: the labelled rows' majority class (their mean, for "
        "R²) predicted for every test row; 'below majority': replicates scoring less.",
        "The regime's probes choose C and λ from grids that reach the majority class and the "
        "mean (config regime.C, regime.lambdas); the probes stage keeps the paper's grids "
        "(probes.C, probes.lambdas).",
        "Generators' best steps (early stopping on a held-out tenth of the pool): "
        + ", ".join(f"{c} seed {s} N_P={n} {p}: {b}" for (c, s, n, p), b in best.items()),
    ],
)
write_table(
    report.pool_table(view, control_view),
    out.pool,
    title="Each rung against the pool size N_P: Δ vs nonlinear V (linear probe)",
    mono=(),
    notes=[
        "Mean Δ over the replicates (seed × labelled draw), the replicates' interval read as one "
        "[low, high], and how many replicates' 95% CIs lie above (↑) or below (↓) 0; the same "
        "labelled and test rows at every pool size. A0 (the look oracle) is the reference; the "
        "smallest ρ is the control, where no rung may gain. Touch 'look + noise': the "
        "positive control, every rung but the diffusion generator's on the look's mean real "
        "touch plus noise (config regime.look_control_snr), where the learnt rungs must gain "
        "as the pool grows.",
    ],
)
write_figure(report.pool_curve_figure(view, control_view), out.pool_curve)
write_figure(report.heatmap_figure(view), out.heatmap)
write_figure(report.curves_figure(view), out.curves)
for note in notes:
    logger.info("%s", note)
