"""TacGen workflow: touch carries physical properties vision cannot see.

Run `snakemake --cores 2` for the embedded default (config/config.yaml), or
`snakemake --cores 2 --configfile config/test.yaml` for the tiny configuration.
"""

from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "rules/common.smk"
include: "rules/report_common.smk"


wildcard_constraints:
    corpus="[a-z][a-z0-9_]*",
    shard=r"\d+",


include: "rules/corpus.smk"
include: "rules/preprocess.smk"
include: "rules/features.smk"
include: "rules/align.smk"
include: "rules/generate.smk"  # issue 12: latent V->T generator
include: "rules/probes.smk"
# --- cost of accuracy (issue 14): the knob registry, then the simulation and features knobs ---
include: "rules/cost_common.smk"
include: "rules/cost_features.smk"
# --- end cost of accuracy, simulation and features knobs ---
# --- policy stage (issue 13) ---
include: "rules/policy.smk"
# --- end policy stage ---
include: "rules/cost.smk"
include: "rules/report.smk"


rule all:
    default_target: True
    input:
        TARGETS,
