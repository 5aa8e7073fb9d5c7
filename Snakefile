"""TacGen workflow: touch carries physical properties vision cannot see.

Run `snakemake --cores 2` for the embedded default (config/config.yaml), or
`snakemake --cores 2 --configfile config/test.yaml` for the tiny configuration.
"""

from pathlib import Path

from snakemake.utils import min_version

from tacgen_lib.estimate.resources import attach_estimated_runtime
from tacgen_lib.runtime.conda_envs import use_gpu_envs
from tacgen_lib.runtime.gpus import attach_gpu_resource, gpu_plan

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "rules/stages.smk"
include: "rules/preload.smk"


rule all:
    default_target: True
    input:
        TARGETS,


# Every job's runtime (its SLURM time limit) from its run-time estimate, with headroom and the
# attempt factor (tacgen_lib/estimate/resources.py); a runtime given with --set-resources wins.
# Attached once, by the main workflow, to its rules and the cost settings' alike (a setting's
# module loads rules/stages.smk, not this file).
# Torch jobs hold a GPU where the run's device computes on one (tacgen_lib/runtime/gpus.py):
# gpu=1 on every rule whose params carry the device, never on a CPU rule; on SLURM each such
# job asks for a GPU, locally --resources gpu=N bounds them (by default one per visible GPU).
# Snakemake gives a cluster executor's run its --jobs as nodes, a local run none. With
# --sdm conda such a run's environments name conda-forge's GPU torch (runtime/conda_envs.py).
attach_estimated_runtime(
    workflow.rules, keep=workflow.resource_settings.overwrite_resources
)
GPU_PLAN = gpu_plan(
    config["device"],
    cluster=workflow.resource_settings.nodes is not None,
    given=workflow.resource_settings.resources or {},
)
if GPU_PLAN.jobs_hold_gpu:
    attach_gpu_resource(
        workflow.rules, keep=workflow.resource_settings.overwrite_resources
    )
    if any(m.name == "CONDA" for m in workflow.deployment_settings.deployment_method):
        use_gpu_envs(workflow.rules, Path.cwd())
if GPU_PLAN.local_limit is not None:
    workflow.register_resource("gpu", GPU_PLAN.local_limit)
