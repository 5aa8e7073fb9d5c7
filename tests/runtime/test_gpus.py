"""Which jobs hold a GPU and how many at once (tacgen_lib.runtime.gpus): the GPUs a job sees,
the plan for each device value on a workstation and a cluster, the `gpu` resource on torch
rules only, the local bound Snakemake enforces when the Snakefile registers it at parse time,
and one GPU per job where several are visible. No GPU is needed: the GPUs are names."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pytest

from tacgen_lib.runtime.gpus import (
    attach_gpu_resource,
    claim_gpu,
    gpu_plan,
    installed_torch_is_cuda,
    run_uses_gpu,
    visible_gpus,
)

ROOT = Path(__file__).resolve().parents[2]


def test_the_gpus_a_job_sees(tmp_path):
    driver = tmp_path / "gpus"
    driver.mkdir()
    for bus in ("0000:01:00.0", "0000:41:00.0"):
        (driver / bus).mkdir()
    assert visible_gpus({}, driver) == ["0", "1"]  # the driver's list, as indices
    assert visible_gpus({}, tmp_path / "absent") == []  # no driver loaded
    # CUDA_VISIBLE_DEVICES wins, read up to its first empty or negative entry (as CUDA does)
    assert visible_gpus({"CUDA_VISIBLE_DEVICES": "2,3"}, driver) == ["2", "3"]
    assert visible_gpus({"CUDA_VISIBLE_DEVICES": "GPU-8f2e,1"}, driver) == ["GPU-8f2e", "1"]
    assert visible_gpus({"CUDA_VISIBLE_DEVICES": ""}, driver) == []
    assert visible_gpus({"CUDA_VISIBLE_DEVICES": "1,-1,2"}, driver) == ["1"]


def test_the_installed_torch_here_is_read_without_importing_it():
    import torch

    assert installed_torch_is_cuda() == (torch.version.cuda is not None)


def test_which_runs_hold_a_gpu():
    def uses(device, cluster=False, gpus=1, cuda=True):
        return run_uses_gpu(device, cluster=cluster, gpus_here=gpus, cuda_build=cuda)

    assert not uses("cpu") and not uses("cpu", cluster=True)
    assert uses("cuda") and uses("cuda", cluster=True, gpus=0, cuda=False)  # a login node
    assert uses("cuda+tf32")
    assert uses("auto") and not uses("auto", gpus=0) and not uses("auto", cuda=False)
    with pytest.raises(ValueError, match="device: auto on a cluster executor.*device: cuda"):
        uses("auto", cluster=True)
    with pytest.raises(ValueError, match="'gpu'"):
        uses("gpu")


def test_the_local_bound_is_one_job_per_visible_gpu_unless_the_user_gave_one():
    plan = gpu_plan("cuda", cluster=False, given={}, gpus_here=3, cuda_build=True)
    assert (plan.jobs_hold_gpu, plan.local_limit) == (True, 3)
    assert gpu_plan("cuda", cluster=False, given={}, gpus_here=0, cuda_build=True).local_limit == 1
    assert gpu_plan("cuda", cluster=False, given={"gpu": 2}, gpus_here=3).local_limit is None
    on_slurm = gpu_plan("cuda", cluster=True, given={}, gpus_here=0, cuda_build=False)
    assert (on_slurm.jobs_hold_gpu, on_slurm.local_limit) == (True, None)  # SLURM places them
    cpu = gpu_plan("cpu", cluster=False, given={}, gpus_here=4, cuda_build=True)
    assert (cpu.jobs_hold_gpu, cpu.local_limit) == (False, None)


def _rule(name, params=(), norun=False):
    return SimpleNamespace(
        name=name, params=SimpleNamespace(keys=lambda: list(params)), norun=norun, resources={}
    )


def test_the_gpu_resource_goes_on_torch_rules_only():
    torch_rule = _rule("train_heads", ("settings", "device"))
    cpu_rule = _rule("probe", ("settings",))
    kept = _rule("extract_vision_features", ("device",))
    kept.resources["gpu"] = 2
    aggregate = _rule("all", ("device",), norun=True)
    attached = attach_gpu_resource(
        [torch_rule, cpu_rule, kept, aggregate], keep={"extract_vision_features": {"gpu": 2}}
    )
    assert attached == ["train_heads"]
    assert torch_rule.resources == {"gpu": 1}
    assert cpu_rule.resources == {} and aggregate.resources == {}
    assert kept.resources == {"gpu": 2}  # the user's --set-resources wins


#: three torch jobs and one CPU job; each torch job refuses to start while another is inside
#: (mkdir is atomic), so two at once fail the run. The plan registers the bound at parse time,
#: as the workflow's Snakefile does.
SNAKEFILE = textwrap.dedent(
    """
    from tacgen_lib.runtime.gpus import attach_gpu_resource, gpu_plan

    rule all:
        input: expand("gpu_{i}.done", i=range(3)), "cpu.done"

    rule on_gpu:
        output: "gpu_{i}.done"
        params: device="cuda"
        shell: "mkdir inside && sleep 0.5 && rmdir inside && touch {output}"

    rule on_cpu:
        output: "cpu.done"
        shell: "touch {output}"

    PLAN = gpu_plan(
        "cuda",
        cluster=workflow.resource_settings.nodes is not None,
        given=workflow.resource_settings.resources or {},
        gpus_here=0,
        cuda_build=True,
    )
    attach_gpu_resource(workflow.rules, keep=workflow.resource_settings.overwrite_resources)
    if PLAN.local_limit is not None:
        workflow.register_resource("gpu", PLAN.local_limit)
    """
)


def _snakemake(workdir: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "snakemake", "--cores", "4", *args],
        cwd=workdir,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


def test_snakemake_holds_the_registered_bound(tmp_path):
    (tmp_path / "Snakefile").write_text(SNAKEFILE)
    proc = _snakemake(tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # (Snakemake prints a registered resource as its Resource object)
    assert re.search(r'Provided resources: gpu=(Resource\("gpu", )?1\b', proc.stderr), proc.stderr
    assert all((tmp_path / f"gpu_{i}.done").exists() for i in range(3))
    # the user's --resources gpu=N is kept, not replaced by the default (jobs without the
    # one-at-a-time guard: three may now run at once)
    given = tmp_path / "given"
    given.mkdir()
    (given / "Snakefile").write_text(
        SNAKEFILE.replace("mkdir inside && sleep 0.5 && rmdir inside && ", "")
    )
    proc = _snakemake(given, "--resources", "gpu=3")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert re.search(r'Provided resources: gpu=(Resource\("gpu", )?3\b', proc.stderr), proc.stderr


def _claimer(locks: Path, gpus: str) -> subprocess.Popen:
    """A process that claims one of `gpus` and holds it until its stdin closes."""
    code = (
        "import sys; from pathlib import Path; from tacgen_lib.runtime.gpus import claim_gpu; "
        f"print(claim_gpu({gpus.split(',')!r}, Path({str(locks)!r})), flush=True); "
        "sys.stdin.read()"
    )
    return subprocess.Popen(
        [sys.executable, "-c", code],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


def test_each_job_takes_a_gpu_no_other_job_holds(tmp_path):
    assert claim_gpu(["0"], tmp_path) is None  # one GPU: nothing to choose
    assert claim_gpu([], tmp_path) is None
    first = _claimer(tmp_path, "0,1")
    assert first.stdout.readline().strip() == "0"
    second = _claimer(tmp_path, "0,1")
    assert second.stdout.readline().strip() == "1"
    third = _claimer(tmp_path, "0,1")  # more jobs than GPUs: shares the first
    assert third.stdout.readline().strip() == "0"
    for proc in (first, third):
        proc.communicate("")
    # the first job ended: its GPU is free again, the second's is still held
    again = _claimer(tmp_path, "0,1")
    assert again.stdout.readline().strip() == "0"
    for proc in (second, again):
        proc.communicate("")
