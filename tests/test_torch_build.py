"""tools/torch_build.py: which torch build setup installs and from where, without a network.
The three cases of a fresh machine: a local CPU wheel (this repository's CI), no local wheel
(PyTorch's CPU index, never PyPI's CUDA torch), and TORCH=cuda; and the build check."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import torch_build  # noqa: E402 - tools/ is not a package

PY = "/venv/bin/python"
TAIL = ("-c", "constraints.txt", "-e", ".[workflow,dev]")


def _plan(asked, installer="uv", wheel=None, driver=False, installed=None):
    return torch_build.plan(
        asked,
        installer=installer,
        python=PY,
        version="2.13.0",
        local_wheel=wheel,
        nvidia_driver=driver,
        installed=installed,
    )


@pytest.fixture
def wheel_dir(tmp_path):
    folder = tmp_path / "wheels"
    folder.mkdir()
    (folder / "torch-2.13.0+cpu-cp311-cp311-manylinux_2_28_x86_64.whl").write_bytes(b"")
    return folder


def test_local_cpu_wheel_is_found_by_version(wheel_dir, tmp_path):
    found = torch_build.local_cpu_wheel(wheel_dir, "2.13.0")
    assert found is not None and found.name.startswith("torch-2.13.0+cpu-")
    assert torch_build.local_cpu_wheel(wheel_dir, "2.12.0") is None
    assert torch_build.local_cpu_wheel(tmp_path / "absent", "2.13.0") is None


@pytest.mark.parametrize("installer", ["uv", "pip"])
def test_a_local_cpu_wheel_is_installed_from_its_folder(wheel_dir, installer):
    got = _plan("cpu", installer, wheel=torch_build.local_cpu_wheel(wheel_dir, "2.13.0"))
    assert (got.build, got.source, got.uninstall) == ("cpu", "local wheels", ())
    base = (
        ("uv", "pip", "install", "-q", "--python", PY, "--compile-bytecode")
        if installer == "uv"
        else (PY, "-m", "pip", "install", "-q")
    )
    assert got.command == (*base, "--find-links", str(wheel_dir), *TAIL)


def test_without_a_local_wheel_torch_comes_from_pytorchs_cpu_index():
    uv = _plan("cpu", "uv")
    assert (uv.build, uv.source) == ("cpu", "pytorch cpu index")
    assert uv.command == (
        *("uv", "pip", "install", "-q", "--python", PY, "--compile-bytecode"),
        *("--torch-backend", "cpu"),
        *TAIL,
    )
    pip = _plan("cpu", "pip")
    assert pip.command == (
        *(PY, "-m", "pip", "install", "-q"),
        *("--extra-index-url", "https://download.pytorch.org/whl/cpu"),
        *TAIL,
    )
    # never a bare PyPI torch (the CUDA build) for cpu, whatever the installer
    for p in (uv, pip):
        assert "--find-links" not in p.command
        assert "--torch-backend" in p.command or torch_build.CPU_INDEX in p.command


def test_torch_cuda_asks_for_a_cuda_build_even_where_a_cpu_wheel_is(wheel_dir):
    wheel = torch_build.local_cpu_wheel(wheel_dir, "2.13.0")
    uv = _plan("cuda", "uv", wheel=wheel)
    assert (uv.build, uv.source) == ("cuda", "pytorch cuda index")
    assert uv.command[-6:] == ("--torch-backend", "auto", *TAIL)
    assert "--find-links" not in uv.command
    exact = _plan("cu126", "uv", wheel=wheel)
    assert exact.command[-6:] == ("--torch-backend", "cu126", *TAIL)
    pip = _plan("cuda", "pip", wheel=wheel)  # PyPI's Linux torch is the CUDA build
    assert (pip.source, pip.command) == ("pypi", (PY, "-m", "pip", "install", "-q", *TAIL))
    pip126 = _plan("cu126", "pip")
    assert pip126.command[-6:] == (
        *("--extra-index-url", "https://download.pytorch.org/whl/cu126"),
        *TAIL,
    )


def test_auto_follows_the_nvidia_driver(wheel_dir):
    wheel = torch_build.local_cpu_wheel(wheel_dir, "2.13.0")
    assert _plan("auto", wheel=wheel, driver=False).source == "local wheels"
    assert _plan("auto", driver=False).source == "pytorch cpu index"
    assert _plan("auto", wheel=wheel, driver=True).build == "cuda"


def test_the_other_build_installed_is_removed_first():
    for installer in ("uv", "pip"):
        assert _plan("cuda", installer, installed="cpu").uninstall[-1] == "torch"
        assert _plan("cpu", installer, installed="cuda").uninstall[-1] == "torch"
        assert _plan("cpu", installer, installed="cpu").uninstall == ()
        assert _plan("cpu", installer, installed=None).uninstall == ()


def test_an_unknown_torch_value_is_refused():
    with pytest.raises(ValueError, match="TORCH='gpu'"):
        _plan("gpu")
    with pytest.raises(ValueError, match="installer"):
        _plan("cpu", "conda")


@pytest.mark.parametrize(
    ("version", "cuda", "build"),
    [("2.13.0+cpu", None, "cpu"), ("2.13.0", "12.8", "cuda"), ("2.13.0+cu126", "12.6", "cuda")],
)
def test_the_build_of_an_installed_torch(version, cuda, build):
    assert torch_build.build_of(version, cuda) == build


def test_the_build_check_accepts_what_was_asked_and_names_both_otherwise():
    assert torch_build.check_build("2.13.0+cpu", None, "cpu", nvidia_driver=True) is None
    assert torch_build.check_build("2.13.0", "12.8", "cuda", nvidia_driver=False) is None
    assert torch_build.check_build("2.13.0+cpu", None, "auto", nvidia_driver=False) is None
    wrong = torch_build.check_build("2.13.0", "12.8", "cpu", nvidia_driver=False)
    assert wrong is not None
    assert "torch 2.13.0 is the cuda build" in wrong and "TORCH=cpu asks for the cpu" in wrong
    other = torch_build.check_build("2.13.0+cpu", None, "cuda", nvidia_driver=False)
    assert other is not None and "is the cpu build" in other and "the cuda build" in other


def test_the_pin_is_read_from_constraints():
    assert torch_build.torch_pin() == "2.13.0"


def test_every_conda_env_names_one_build_and_can_name_either():
    """envs/*.yaml follow setup's choice: all name the same build (conda-forge's pytorch-cpu,
    or pytorch-gpu after `TORCH=cuda` setup), and `conda_env_text` moves each between the two
    and back without touching anything else."""
    envs = sorted((ROOT / "envs").glob("*.yaml"))
    assert envs
    builds = set()
    for path in envs:
        text = path.read_text()
        named = [b for b, pkg in torch_build.CONDA_PACKAGES.items() if f"  - {pkg}=" in text]
        assert len(named) == 1, path.name
        builds.add(named[0])
        assert torch_build.conda_env_text(text, named[0]) == text, path.name
        cpu = torch_build.conda_env_text(text, "cpu")
        gpu = torch_build.conda_env_text(text, "cuda")
        assert "  - pytorch-gpu=2.*" in gpu and "pytorch-cpu" not in gpu, path.name
        assert "  - pytorch-cpu=2.*" in cpu and "pytorch-gpu" not in cpu, path.name
        assert torch_build.conda_env_text(gpu, "cpu") == cpu, path.name
        assert len(gpu.splitlines()) == len(text.splitlines()), path.name
    assert len(builds) == 1, f"envs/*.yaml name different torch builds: {builds}"
