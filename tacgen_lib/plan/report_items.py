"""Report items the rules share: the Features page's pretraining items, the probes' pages, and
the optional inputs of the findings page (rules/report.smk)."""

from __future__ import annotations

from typing import Any

from snakemake.io import directory, report

from tacgen_lib.plan.features import VISIBILITY_EDGE
from tacgen_lib.plan.policy import POLICY_DIR
from tacgen_lib.plan.probes import PROBE_REPORT
from tacgen_lib.plan.regime import REGIME_DIR
from tacgen_lib.report_pages import category


def features_report_item(path: str, caption: str, labels: dict[str, str], shown: bool) -> Any:
    """`path` as a report item of the Features page where `shown` (the backbones learned
    something, and this run is not one setting of a cost knob); else the plain path, still
    made and hashed but left out of the report rather than shown as a placeholder."""
    if not shown:
        return path
    return report(
        path,
        caption=caption,
        category=category("Features"),
        subcategory="Backbone pretraining",
        labels=labels,
    )


def probe_report_dir(name: str, label: str) -> Any:
    """A directory of figures, one per probe family, each its own report item."""
    return report(
        directory(f"{PROBE_REPORT}/{name}"),
        patterns=["{family}.png"],
        caption=f"../workflow/report/probe_{name}.rst",
        category=category("Probes"),
        subcategory=label,
        labels={"family": "{family}"},
    )


def probe_report_item(name: str, ext: str, caption: str, label: str, page: str = "Probes") -> Any:
    """One table or figure of the probes' pages."""
    return report(
        f"{PROBE_REPORT}/{name}.{ext}",
        caption=f"../workflow/report/probe_{caption}.rst",
        category=category(page),
        subcategory="Figures" if ext == "png" else "Tables",
        labels={"item": label},
    )


def findings_inputs(
    *,
    policy: bool,
    regime: bool,
    visibility: bool,
    backbones: bool,
    transfer: bool,
    pixel: bool,
) -> dict[str, str]:
    """The stage summaries the findings page reads beside the probes and the generation, each
    where its stage runs: the policy's, the regime's, the visibility check (where a simulated
    corpus runs), the backbone families' (where a family other than the main DAG's runs), the
    transfer stage's and the pixel generators' (where they are judged)."""
    inputs = {}
    if policy:
        inputs |= {
            f"policy_{t}": f"{POLICY_DIR}/{t}.parquet" for t in ("summary", "deltas", "sweep")
        }
    if regime:
        inputs["regime"] = f"{REGIME_DIR}/summary.parquet"
        inputs["regime_control"] = f"{REGIME_DIR}/look_control.parquet"
    if visibility:
        inputs["visibility"] = VISIBILITY_EDGE
    if backbones:
        inputs["backbones"] = "results/backbones/summary.parquet"
    if transfer:
        inputs["transfer"] = "results/transfer/summary.parquet"
    if pixel:
        inputs["pixel"] = "results/pixel/summary.parquet"
    return inputs
