"""The report's items that rule files share (included before the stages)."""

from tacgen_lib.features.settings import backbones_pretrained
from tacgen_lib.plan.report_items import features_report_item, findings_inputs

#: whether the backbones learned anything: DINO epochs, or an official checkpoint. Without, the
#: pretraining curve and the pretrained-vs-random table (Δ = 0 by construction) are still made
#: and hashed, but left out of the report rather than shown as placeholders.
PRETRAINED = backbones_pretrained(config["features"])


#: this run is one setting of a cost knob (a module of rules/stages.smk, rules/cost_common.smk):
#: its outputs feed the cost page, never the report's own pages. The report flag is part of a
#: rule's output and a module's copy keeps it; `use rule ... with: output:` could only replace
#: the whole output, which replace_prefix then leaves unmoved, so the setting's config says it
COST_SETTING_RUN = bool(config["cost"].get("setting"))
#: whether the Features page shows the pretraining items
FEATURES_SHOWN = PRETRAINED and not COST_SETTING_RUN
