"""The findings page: every evidence branch's headline with its control and a verdict
generated from the numbers, and the decisions edge of those verdicts (rule findings)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.generate.visibility import visibility_gate
from tacgen_lib.io import edges, log
from tacgen_lib.report import findings
from tacgen_lib.report.write import write_table

logger = log.for_rule(snakemake)
parts = [
    findings.probe_findings(edges.read(snakemake.input.probes).frame),
    findings.generation_findings(
        edges.read(snakemake.input.generation).frame, snakemake.params.generate_ref
    ),
]
if snakemake.params.policy:
    parts.append(
        findings.policy_findings(
            edges.read(snakemake.input.policy_summary).frame,
            edges.read(snakemake.input.policy_deltas).frame,
            edges.read(snakemake.input.policy_sweep).frame,
        )
    )
visibility = None
if snakemake.params.visibility:
    visibility = edges.read(snakemake.input.visibility).frame
    parts.insert(0, findings.visibility_findings(visibility, snakemake.params.gate))
if snakemake.params.regime:
    gates = [
        visibility_gate(visibility, c, snakemake.params.gate)
        for c in snakemake.params.regime_corpora
        # the rho grid is checked on its first corpus (rule visibility_check)
        if visibility is not None and snakemake.params.gate and c in set(visibility["corpus"])
    ]
    parts.append(
        findings.regime_findings(
            edges.read(snakemake.input.regime).frame,
            " ".join(g.sentence() for g in gates),
            gate_passed=all(g.passed for g in gates),
            control=edges.read(snakemake.input.regime_control).frame,
            snr=snakemake.params.look_control_snr,
        )
    )
if snakemake.params.pixel:
    # a report table with wall times, not an edge (rule aggregate_pixel)
    parts.append(findings.pixel_findings(pd.read_parquet(snakemake.input.pixel)))
if snakemake.params.backbones:
    parts.append(
        findings.backbone_findings(
            edges.read(snakemake.input.backbones).frame,
            snakemake.params.backbones["main"],
            snakemake.params.backbones["order"],
        )
    )
if snakemake.params.transfer:
    parts.append(findings.transfer_findings(edges.read(snakemake.input.transfer).frame))
table, decided = findings.gather(parts)
edges.write(snakemake.output.decisions, decided, key="decision_id", producer=snakemake.rule)
write_table(
    table,
    snakemake.output.html,
    title=f"Findings of run {snakemake.params.run_name}",
    mono=(),
    notes=[
        "Intervals are 95 %: fixed-test bootstrap for probes and policy (paired for Δ), a "
        "t-interval over generator seeds for generation. A verdict calls a difference real "
        "only when its interval excludes 0; each sentence is generated from the numbers beside "
        "it (tacgen_lib.report.claims). The page column names the report page with the detail. "
        "Regime rows read the first seed's fixed-test bootstrap CIs; the transfer row's "
        "intervals resample test objects."
    ],
)
for r in table.itertuples():
    logger.info("%s: %s", r.evidence, r.verdict)
logger.info("%d decisions -> %s", len(decided), snakemake.output.decisions)
