"""GPU requests without a cluster: config/test.yaml planned (a dry run, no jobs) under
profiles/slurm with device: cuda and device: cpu, and each job's sbatch arguments built by
snakemake-executor-plugin-slurm's own functions from the resources Snakemake gave it. With cuda
every torch rule (a rule whose script picks a device) asks for one GPU and no CPU rule does;
with cpu no job does; device: auto is refused for a cluster. Locally the `gpu` resource is on
the torch rules only (tacgen_lib/runtime/gpus.py)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path
from types import SimpleNamespace

import pytest
from snakemake_run import SNAKEMAKE, copy_tree

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh copy of the workflow: no results, so a dry run plans every job."""
    return copy_tree(tmp_path_factory.mktemp("slurm_gpu"))


def dry_run(workdir: Path, *args: str) -> subprocess.CompletedProcess:
    """A dry run of config/test.yaml in `workdir`."""
    return subprocess.run(
        [*SNAKEMAKE, "-n", "--configfile", "config/test.yaml", *args],
        cwd=workdir,
        capture_output=True,
        text=True,
        timeout=300,
    )


def planned_jobs(output: str) -> list[tuple[str, int, dict[str, object]]]:
    """(rule, threads, resources) of every job a dry run printed; integer values as int."""
    jobs = []
    for block in re.split(r"\n(?=(?:local)?rule \w+:)", output):
        m = re.match(r"(?:local)?rule (\w+):", block)
        res = re.search(r"^\s+resources: (.*)$", block, re.M)
        if not m or not res:
            continue
        threads = re.search(r"^\s+threads: (\d+)$", block, re.M)
        resources: dict[str, object] = {}
        for item in res.group(1).split(", "):
            key, _, value = item.partition("=")
            resources[key] = int(value) if value.isdigit() else value
        jobs.append((m.group(1), int(threads.group(1)) if threads else 1, resources))
    return jobs


class _Resources(dict):
    """A job's resources as the plugin reads them (`.get` and attributes)."""

    __getattr__ = dict.get


def sbatch_arguments(rule: str, threads: int, resources: dict[str, object]) -> str:
    """The sbatch call snakemake-executor-plugin-slurm builds for such a job."""
    from snakemake_executor_plugin_slurm.submit_string import get_submit_command
    from snakemake_executor_plugin_slurm.utils import set_gres_string

    job = SimpleNamespace(
        name=rule, threads=threads, resources=_Resources(resources), is_group=lambda: False
    )
    params = dict(
        run_uuid="uuid",
        slurm_logfile="log",
        comment_str=f"rule_{rule}",
        account="",
        partition="",
        workdir=str(ROOT),
    )
    return get_submit_command(job, params) + set_gres_string(job)


def torch_rules() -> set[str]:
    """The rules whose script picks a device (`params.device`), read from rules/*.smk."""
    pickers = {
        p.name
        for p in (ROOT / "workflow" / "scripts").glob("*.py")
        if re.search(r"params\.device\b", p.read_text())
    }
    names = set()
    for smk in (ROOT / "rules").glob("*.smk"):
        for block in re.split(r"(?m)^(?=\s*rule \w+:)", smk.read_text()):
            name = re.search(r"rule (\w+):", block)
            script = re.search(r"scripts/(\w+\.py)", block)
            if name and script and script.group(1) in pickers:
                names.add(name.group(1))
    return names


@pytest.fixture(scope="module")
def slurm_plans(workdir: Path) -> dict[str, list]:
    out = {}
    for device in ("cuda", "cpu"):
        proc = dry_run(workdir, "--profile", "profiles/slurm", "--config", f"device={device}")
        assert proc.returncode == 0, proc.stderr[-3000:]
        out[device] = planned_jobs(proc.stdout)
        assert len(out[device]) > 50, proc.stdout[-2000:]
    return out


def test_on_slurm_torch_jobs_ask_for_a_gpu_only_when_the_device_is_cuda(slurm_plans):
    torch = torch_rules()
    asked = {}
    for device, jobs in slurm_plans.items():
        for rule, threads, resources in jobs:
            call = sbatch_arguments(rule, threads, resources)
            cpus = resources.get("cpus_per_task", threads)
            assert call.startswith("sbatch ") and f"--cpus-per-task={cpus}" in call, call
            asked.setdefault(device, {}).setdefault(rule, set()).add("--gpus=1" in call)
            if device == "cpu" or rule not in torch:
                assert "--gpus" not in call and "--gres" not in call, (device, rule, call)
    gpu_rules = {rule for rule, got in asked["cuda"].items() if got == {True}}
    # every torch rule of test.yaml's DAG asks for one GPU per job, and only they do
    assert gpu_rules == torch & set(asked["cuda"]), gpu_rules ^ (torch & set(asked["cuda"]))
    assert {"train_heads", "extract_vision_features", "train_generator", "train_policy"} <= (
        gpu_rules
    )
    assert not any(True in got for got in asked["cpu"].values())
    example = next(j for j in slurm_plans["cuda"] if j[0] == "train_heads")
    print("cuda train_heads:", sbatch_arguments(*example))


def test_auto_is_refused_for_a_cluster_executor(workdir):
    proc = dry_run(workdir, "--profile", "profiles/slurm", "--config", "device=auto")
    said = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert "device: auto on a cluster executor" in said and "set device: cuda" in said, said


def test_locally_the_gpu_resource_is_on_torch_rules_only(workdir):
    """A local run with device: cuda: gpu=1 on every torch job, on no other (with device: cpu
    no job holds one: the SLURM plan above)."""
    proc = dry_run(workdir, "--cores", "2", "--config", "device=cuda")
    assert proc.returncode == 0, proc.stderr[-3000:]
    jobs = planned_jobs(proc.stdout)
    with_gpu = {rule for rule, _t, res in jobs if res.get("gpu") == 1}
    assert with_gpu == torch_rules() & {rule for rule, _t, _r in jobs}
    assert all(res.get("gpu") in (None, 1) for _r, _t, res in jobs)
