"""The conda environments of `--sdm conda` follow the run's `device`.

envs/*.yaml (tracked, never rewritten) name conda-forge's CPU torch, `pytorch-cpu`. A run whose
torch jobs hold a GPU (`tacgen_lib.runtime.gpus.gpu_plan`) and deploys with conda gives every
rule a copy of its environment file naming `pytorch-gpu` instead (`conda_env_text`), written
under the working directory's `.snakemake/` (`GPU_ENVS`) with the path of this repository for
its editable install (the tracked files name it relative to envs/). Snakemake builds a
separate environment for each file's content, so a CPU and a GPU run of one checkout each get
their own, and switching back to cpu uses the tracked files again.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = [
    "CONDA_PACKAGES",
    "GPU_ENVS",
    "conda_env_text",
    "conda_line",
    "use_gpu_envs",
]

#: conda-forge's metapackages for each torch build
CONDA_PACKAGES = {"cpu": "pytorch-cpu", "cuda": "pytorch-gpu"}
#: where a GPU run's copies of envs/*.yaml are written, under the working directory
GPU_ENVS = Path(".snakemake") / "tacgen-envs" / "cuda"

_TORCH_LINE = re.compile(r"^  - pytorch-(?:cpu|gpu)=.*$", re.MULTILINE)
_EDITABLE = re.compile(r"^(\s*- --editable )\.\.(\s.*)?$", re.MULTILINE)


def conda_line(build: str) -> str:
    """The envs/*.yaml dependency line of torch's `build` (cpu, cuda)."""
    return f"  - {CONDA_PACKAGES[build]}=2.*   # {build} build (tacgen_lib.runtime.conda_envs)"


def conda_env_text(text: str, build: str, repository: Path | None = None) -> str:
    """An envs/*.yaml file's text with its torch line naming `build` (exactly one such line),
    and where `repository` is given, its editable install (`--editable ..`, relative to
    envs/) naming that directory instead."""
    if len(_TORCH_LINE.findall(text)) != 1:
        raise ValueError("expected one '  - pytorch-cpu=...' or '  - pytorch-gpu=...' line")
    text = _TORCH_LINE.sub(conda_line(build), text)
    if repository is not None:
        text = _EDITABLE.sub(lambda m: f"{m.group(1)}{repository}{m.group(2) or ''}", text)
    return text


def use_gpu_envs(rules: Iterable[Any], workdir: Path) -> list[str]:
    """Point every rule's conda environment (a file relative to its Snakefile's directory,
    `rule.basedir`) at its GPU copy under `workdir / GPU_ENVS`, written there where it is
    missing or differs. Returns the names of the rules moved."""
    moved = []
    out = Path(workdir) / GPU_ENVS
    for rule in rules:
        env = rule.conda_env
        if not isinstance(env, str) or not env.endswith((".yaml", ".yml")):
            continue
        source = Path(rule.basedir.get_path_or_uri(secret_free=True)) / env
        if not source.is_file():
            continue
        source = source.resolve()
        text = conda_env_text(source.read_text(), "cuda", repository=source.parent.parent)
        target = out / source.name
        if not target.is_file() or target.read_text() != text:
            out.mkdir(parents=True, exist_ok=True)
            part = target.with_name(f".{target.name}.{os.getpid()}")
            part.write_text(text)
            os.replace(part, target)  # whole, also where two processes write it at once
        rule.conda_env = str(target.resolve())
        moved.append(rule.name)
    return moved
