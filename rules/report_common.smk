"""Helpers of the report's items that rule files share (included before the stages)."""

from tacgen_lib.features.settings import backbones_pretrained

#: whether the backbones learned anything: DINO epochs, or an official checkpoint. Without, the
#: pretraining curve and the pretrained-vs-random table (Δ = 0 by construction) are still made
#: and hashed, but left out of the report rather than shown as placeholders.
PRETRAINED = backbones_pretrained(config["features"])


#: this run is one setting of a cost knob (a module of this Snakefile, rules/cost_common.smk):
#: its outputs feed the cost page, never the report's own pages
COST_SETTING_RUN = bool((config.get("cost") or {}).get("setting"))


def features_report_item(path, caption, labels):
    """`path` as a report item of the Features page where the backbones were pretrained."""
    if not PRETRAINED or COST_SETTING_RUN:
        return path
    return report(
        path,
        caption=caption,
        category=category("Features"),
        subcategory="Backbone pretraining",
        labels=labels,
    )


def findings_visibility_inputs(wildcards):
    """The visibility check the findings page reads, where a simulated corpus runs."""
    return {"visibility": VISIBILITY_EDGE} if SIM_CORPORA else {}


def findings_regime_inputs(wildcards):
    """The regime summary the findings page reads, where the regime runs."""
    return {"regime": f"{REGIME_DIR}/summary.parquet"} if REGIME_CORPORA else {}


def findings_backbone_inputs(wildcards):
    """The backbone families' summary the findings page reads, where a family other than the
    main DAG's runs (the main family's rows are the probe rows already on the page)."""
    return {"backbones": "results/backbones/summary.parquet"} if FAMILY_FINDINGS else {}


def findings_transfer_inputs(wildcards):
    """The transfer stage's summary the findings page reads, where the stage runs."""
    return {"transfer": "results/transfer/summary.parquet"} if TRANSFER_CORPUS else {}


def findings_pixel_inputs(wildcards):
    """The pixel generators' summary the findings page reads, where they are judged."""
    return {"pixel": "results/pixel/summary.parquet"} if PIXEL_CORPORA else {}


def findings_policy_inputs(wildcards):
    """The policy summaries the findings page reads, where the policy stage runs."""
    if not POLICY_ON:
        return {}
    return {
        f"policy_{t}": f"{POLICY_DIR}/{t}.parquet"
        for t in ("summary", "deltas", "sweep")
    }
