"""The probes stage's names (tacgen_lib.plan.probes); included by probes.smk."""

from tacgen_lib.plan.probes import (
    PROBE_DIR,
    PROBE_EDGES,
    PROBE_FIGURES,
    PROBE_REPORT,
    PROBE_TABLES,
    ROBUSTNESS_TABLES,
)
from tacgen_lib.plan.report_items import probe_report_dir, probe_report_item
from tacgen_lib.probes.protocol_variants import PROTOCOLS

PROBES = config["probes"]
PROBE_FAMILIES = PLANS.probes.families
# probe robustness: every family under raw, the robustness families under each
# other protocol variant (not where it equals raw); (family, protocol) pairs
ROBUST = PLANS.probes.robustness
PROBE_JOBS = PLANS.probes.jobs
