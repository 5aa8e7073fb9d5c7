"""Cost of accuracy (docs/cost.md): the knobs of config `cost.knobs` (tacgen_lib.plan.cost),
each setting a module of the stages' rules; included by cost.smk.

For a swept knob every setting (and replicate) becomes a Snakemake module of rules/stages.smk
with the knob's config keys set; the module's copies of the main rules the knob reruns write
under `results/cost/{knob}/{setting}/` (`replace_prefix`), and read the main run's edges for
everything else. Free knobs rerun nothing. Both kinds go through rule cost_knob_points with a
plan of setting runs.
"""

from tacgen_lib.cost.knobs import KNOBS
from tacgen_lib.plan.cost import COST_POINTS, CostPlan

TARGETS += ["results/report/cost_of_accuracy.html"]

COST_PLAN = CostPlan.from_config(config, PLANS)

# One module per setting: the stages' rules with the setting's config, its rerun rules renamed
# `<module>_<rule>`. (`use rule` takes its rule list literally; the list comes from KNOBS, so
# the statement's own call is made here.)
for _module, (_run, _rules) in COST_PLAN.modules().items():
    workflow.module(
        _module,
        snakefile=str(WORKFLOW_ROOT / "rules" / "stages.smk"),
        config=_run.config,
        replace_prefix=_run.replace_prefix,
    )
    workflow.userule(rules=_rules, from_module=_module, name_modifier=f"{_module}_*")(
        None
    )
