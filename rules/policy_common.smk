"""The policy stage's names (tacgen_lib.plan.policy); included by policy.smk."""

from tacgen_lib.plan.policy import (
    POLICY_DIR,
    POLICY_FIGURES,
    POLICY_REPORT,
    POLICY_TABLES,
)
from tacgen_lib.policy.policy_cells import CELL_CONSTRAINTS as POLICY_CELL_CONSTRAINTS
from tacgen_lib.policy.policy_cells import CELL_PATTERN as POLICY_CELL_PATTERN

POLICY = config["policy"]
POLICY_SETTINGS = PLANS.policy.settings
POLICY_CELLS = PLANS.policy.cells
# The stage needs the heads of a simulated paired corpus: a config without that corpus (for
# example real data only, --replace-workflow-config) leaves the policy stage out of `all`.
POLICY_ON = PLANS.policy.on
