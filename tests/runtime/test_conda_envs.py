"""The conda environments follow the run's device (tacgen_lib.runtime.conda_envs): the tracked
envs/*.yaml all name conda-forge's CPU torch and are never rewritten; a GPU run's rules get
copies naming `pytorch-gpu`, with this repository's path for the editable install."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
import yaml

from tacgen_lib.runtime.conda_envs import (
    CONDA_PACKAGES,
    GPU_ENVS,
    conda_env_text,
    use_gpu_envs,
)

ROOT = Path(__file__).resolve().parents[2]
ENVS = sorted((ROOT / "envs").glob("*.yaml"))


def test_every_tracked_env_names_the_cpu_build_and_can_name_either():
    """envs/*.yaml name pytorch-cpu (setup never rewrites them); `conda_env_text` moves each
    to pytorch-gpu and back without touching anything else."""
    assert ENVS
    for path in ENVS:
        text = path.read_text()
        assert f"  - {CONDA_PACKAGES['cpu']}=" in text, path.name
        assert CONDA_PACKAGES["cuda"] not in text, path.name
        assert conda_env_text(text, "cpu") == text, path.name
        gpu = conda_env_text(text, "cuda")
        assert "  - pytorch-gpu=2.*" in gpu and "pytorch-cpu" not in gpu, path.name
        assert conda_env_text(gpu, "cpu") == text, path.name
        assert len(gpu.splitlines()) == len(text.splitlines()), path.name


def test_an_env_without_one_torch_line_is_refused():
    with pytest.raises(ValueError, match="one '  - pytorch-cpu"):
        conda_env_text("dependencies:\n  - numpy\n", "cuda")


def test_a_gpu_run_points_each_rule_at_a_gpu_copy_of_its_env(tmp_path):
    rules_dir = SimpleNamespace(get_path_or_uri=lambda secret_free: str(ROOT / "rules"))
    heads = SimpleNamespace(name="train_heads", conda_env="../envs/align.yaml", basedir=rules_dir)
    bare = SimpleNamespace(name="all", conda_env=None, basedir=rules_dir)
    moved = use_gpu_envs([heads, bare], tmp_path)
    assert moved == ["train_heads"] and bare.conda_env is None
    copy = Path(heads.conda_env)
    assert copy == (tmp_path / GPU_ENVS / "align.yaml").resolve()
    env = yaml.safe_load(copy.read_text())
    assert "pytorch-gpu=2.*" in env["dependencies"]
    pip = next(d["pip"] for d in env["dependencies"] if isinstance(d, dict))
    assert f"--editable {ROOT}" in pip  # the repository itself, wherever the copy lies
    assert (ROOT / "envs" / "align.yaml").read_text().count("pytorch-cpu") == 1  # untouched
    # a second parse (another run, a cluster job) finds the same copy and leaves it
    before = copy.stat().st_mtime_ns
    again = SimpleNamespace(name="train_heads", conda_env="../envs/align.yaml", basedir=rules_dir)
    use_gpu_envs([again], tmp_path)
    assert again.conda_env == heads.conda_env and copy.stat().st_mtime_ns == before
