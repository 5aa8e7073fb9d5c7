"""TacGen workflow: touch carries physical properties vision cannot see.

Run `snakemake --cores 2` for the embedded default (config/config.yaml), or
`snakemake --cores 2 --configfile config/test.yaml` for the tiny configuration.
"""

from snakemake.utils import min_version

from tacgen_lib.estimate.resources import attach_estimated_runtime

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "rules/common.smk"
include: "rules/preload.smk"
include: "rules/report_common.smk"


wildcard_constraints:
    corpus="[a-z][a-z0-9_]*",
    shard=r"\d+",


include: "rules/corpus.smk"
include: "rules/preprocess.smk"
include: "rules/features.smk"
include: "rules/align.smk"
include: "rules/generate.smk"
include: "rules/regime.smk"
include: "rules/pixel.smk"
include: "rules/language.smk"
include: "rules/probes.smk"
include: "rules/backbones.smk"
include: "rules/transfer.smk"
include: "rules/policy.smk"
include: "rules/cost.smk"
include: "rules/report.smk"


rule all:
    default_target: True
    input:
        TARGETS,


# Every job's runtime (its SLURM time limit) from its run-time estimate, with headroom and the
# attempt factor (tacgen_lib/estimate/resources.py); a runtime given with --set-resources wins.
# Attached once, by the main workflow, to its rules and the cost settings' alike.
if not (config.get("cost") or {}).get("setting"):
    attach_estimated_runtime(
        workflow.rules, keep=workflow.resource_settings.overwrite_resources
    )
