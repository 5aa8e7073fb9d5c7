"""Cost of accuracy (docs/cost.md): the knobs of config `cost.knobs` (tacgen_lib.plan.cost),
each setting a module of the stages' rules; included by cost.smk.

For a swept knob every setting (and replicate) becomes a Snakemake module of rules/stages.smk
with the knob's config keys set; the module's copies of the main rules the knob reruns write
under `results/cost/{knob}/{setting}/` (`replace_prefix`), and read the main run's edges for
everything else. Free knobs rerun nothing. Both kinds go through rule cost_knob_points with a
plan of setting runs.
"""

from tacgen_lib.cost.knobs import KNOBS
from tacgen_lib.plan.cost import COST_MODULES_DIR, COST_POINTS, CostPlan, write_source

TARGETS += ["results/report/cost_of_accuracy.html"]

COST_PLAN = CostPlan.from_config(config, PLANS)

# One module per setting, in Snakemake's own statements: `module <name>:` with the setting's
# config and replace_prefix, then `use rule <the rules it reruns> from <name> as <name>_*`.
# The names come from config cost.knobs, so the plan writes the statements when the workflow is
# parsed (CostPlan.modules_source), to a file of the run's .snakemake/ folder (write_source),
# and they are included here. A setting's own module sweeps nothing and includes nothing.
if COST_PLAN.modules():
    COST_MODULES = COST_PLAN.modules_source(
        "COST_PLAN", 'str(WORKFLOW_ROOT / "rules" / "stages.smk")'
    )

    include: write_source(COST_MODULES_DIR, COST_MODULES)
