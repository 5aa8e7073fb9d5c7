"""Which jobs hold a GPU, how many at once, and which GPU a job takes.

A run whose `device` computes on a GPU gives every torch rule (a rule whose params carry
`device`: tests/runtime/test_device.py checks that exactly the torch scripts' rules do) the
resource ``gpu=1``; CPU rules never hold one. The same resource serves both executors:

- locally, Snakemake's `--resources gpu=N` bounds the torch jobs on the GPUs at once (CPU jobs
  run beside them on the cores); where the user gives no `gpu`, the Snakefile registers one job
  per visible GPU (`visible_gpus`), one where none is seen;
- on SLURM, snakemake-executor-plugin-slurm turns ``gpu=1`` into ``sbatch --gpus=1``
  (tests/test_slurm_gpu.py builds the submission arguments).

`device: auto` decides per job where its torch sees a GPU: on a cluster jobs would compute on
whatever their nodes have, so a run for a cluster executor refuses it (`run_uses_gpu`); locally
it holds the resource where this machine shows a GPU and torch is a CUDA build.

With several GPUs visible to a job (a workstation), `claim_gpu` gives it one no other job of
this user holds (a lock file per GPU, released when the job's process ends, also when it is
killed), so jobs on different GPUs never share one; `tacgen_lib.runtime.device.torch_device`
calls it before CUDA is first touched and narrows CUDA_VISIBLE_DEVICES to it.

Imports no torch (the Snakefile calls it at parse time).
"""

from __future__ import annotations

import fcntl
import os
import re
import tempfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

__all__ = [
    "GpuPlan",
    "attach_gpu_resource",
    "claim_gpu",
    "gpu_plan",
    "installed_torch_is_cuda",
    "lock_dir",
    "run_uses_gpu",
    "visible_gpus",
]

#: where the NVIDIA kernel driver lists the machine's GPUs (one directory per GPU)
NVIDIA_GPUS = Path("/proc/driver/nvidia/gpus")
#: the resource a torch job holds on a GPU (the SLURM plugin's name for a GPU request)
RESOURCE = "gpu"


def visible_gpus(
    environ: Mapping[str, str] | None = None, driver_gpus: Path = NVIDIA_GPUS
) -> list[str]:
    """The GPUs a job started here would see, as CUDA_VISIBLE_DEVICES names them: its entries
    where it is set (up to the first empty or negative one, where CUDA stops reading), else
    one index per GPU the NVIDIA driver lists ("0", "1", ...); none without a driver."""
    environ = os.environ if environ is None else environ
    if "CUDA_VISIBLE_DEVICES" in environ:
        out = []
        for entry in environ["CUDA_VISIBLE_DEVICES"].split(","):
            entry = entry.strip()
            if not entry or entry.startswith("-"):
                break
            out.append(entry)
        return out
    try:
        n = sum(1 for p in driver_gpus.iterdir() if p.is_dir())
    except OSError:
        return []
    return [str(i) for i in range(n)]


def installed_torch_is_cuda() -> bool:
    """Whether the installed torch is a CUDA build, from its version label without importing
    it: ``+cpu`` (and ``+rocm...``) no, ``+cuNNN`` or no label (PyPI's Linux wheel) yes."""
    try:
        label = metadata.version("torch").partition("+")[2]
    except metadata.PackageNotFoundError:
        return False
    return label == "" or label.startswith("cu")


def run_uses_gpu(device: str, *, cluster: bool, gpus_here: int, cuda_build: bool) -> bool:
    """Whether the torch jobs of a run with config `device` hold a GPU. ``cpu`` never,
    ``cuda`` always; ``auto`` on a cluster executor is refused (each job would compute on
    whatever its node has, a CPU where the node has no GPU), locally where this machine
    shows `gpus_here` > 0 GPUs and torch is a CUDA build (`cuda_build`)."""
    base = device.partition("+")[0]
    if base == "cpu":
        return False
    if base == "cuda":
        return True
    if base != "auto":
        raise ValueError(f"device {device!r}: expected cpu, cuda or auto")
    if cluster:
        raise ValueError(
            "config device: auto on a cluster executor: each job would compute on its node's "
            "device, on the CPU where the node has no GPU, without saying so; set device: cuda "
            "(every torch job asks for a GPU) or device: cpu"
        )
    return gpus_here > 0 and cuda_build


@dataclass(frozen=True)
class GpuPlan:
    """What a run does about GPUs: whether torch jobs hold ``gpu=1`` (`jobs_hold_gpu`) and the
    local bound to register (`local_limit`: None where the user gave one with `--resources`,
    on a cluster, or where no job holds a GPU)."""

    jobs_hold_gpu: bool
    local_limit: int | None


def gpu_plan(
    device: str,
    *,
    cluster: bool,
    given: Iterable[str],
    gpus_here: int | None = None,
    cuda_build: bool | None = None,
) -> GpuPlan:
    """The GPU plan of a run with config `device`: `cluster` where Snakemake submits jobs to
    a cluster executor, `given` the resources the user set (`--resources`). Locally the bound
    is one job per visible GPU (`visible_gpus`), at least one; `gpus_here` and `cuda_build`
    default to this machine's."""
    gpus_here = len(visible_gpus()) if gpus_here is None else gpus_here
    cuda_build = installed_torch_is_cuda() if cuda_build is None else cuda_build
    holds = run_uses_gpu(device, cluster=cluster, gpus_here=gpus_here, cuda_build=cuda_build)
    limit = None
    if holds and not cluster and RESOURCE not in set(given):
        limit = max(1, gpus_here)
    return GpuPlan(jobs_hold_gpu=holds, local_limit=limit)


def attach_gpu_resource(rules: Iterable[Any], *, keep: Mapping[str, Any]) -> list[str]:
    """Give every torch rule (params with a `device`) the resource ``gpu=1``, but a rule named
    in `keep` with a `gpu` of its own (`--set-resources rule:gpu=N`, a profile's
    `set-resources:`). Returns the names of the rules given one."""
    attached = []
    for rule in rules:
        if rule.norun or "device" not in rule.params.keys():
            continue
        if RESOURCE in (keep.get(rule.name) or {}):
            continue
        rule.resources[RESOURCE] = 1
        attached.append(rule.name)
    return attached


def lock_dir() -> Path:
    """This user's directory of GPU locks (in the system's temporary directory)."""
    return Path(tempfile.gettempdir()) / f"tacgen-gpu-locks-{os.getuid()}"


#: the lock this process holds (gpu name, open file), kept for the process's lifetime
_HELD: dict[str, Any] = {}


def claim_gpu(gpus: list[str], locks: Path | None = None) -> str | None:
    """One of `gpus` (CUDA_VISIBLE_DEVICES names) for this process: the first no other process
    holds, its lock kept until this process ends; the one this process claimed before, if
    any; None where there is nothing to choose (fewer than two GPUs). Where every GPU is held
    (a `--resources gpu=N` above the number of GPUs), the first, shared."""
    if len(gpus) < 2:
        return None
    if "gpu" in _HELD:
        return _HELD["gpu"]
    locks = lock_dir() if locks is None else locks
    locks.mkdir(parents=True, exist_ok=True)
    for gpu in gpus:
        handle = open(locks / f"gpu-{re.sub(r'[^A-Za-z0-9_.-]', '_', gpu)}.lock", "a")  # noqa: SIM115 - held for the process's life
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _HELD.update(gpu=gpu, handle=handle)
        return gpu
    return gpus[0]
