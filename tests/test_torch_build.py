"""tools/torch_build.py: which torch build setup installs and from where, without a network.
The cases of a fresh machine: a local CPU wheel (this repository's CI), no local wheel
(PyTorch's CPU index, never PyPI's CUDA torch), TORCH=cuda (a local CUDA wheel or the CUDA
index); the build remembered between setups (`make setup TORCH=cuda` then a plain `make run`
keeps CUDA); the build check and the GPU check's messages; and that setup writes no tracked
file."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

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


CPU_WHEEL = "torch-2.13.0+cpu-cp311-cp311-manylinux_2_28_x86_64.whl"
CUDA_WHEELS = (
    "torch-2.13.0+cu126-cp311-cp311-manylinux_2_28_x86_64.whl",
    "torch-2.13.0+cu128-cp311-cp311-manylinux_2_28_x86_64.whl",
)


@pytest.fixture
def wheel_dir(tmp_path):
    folder = tmp_path / "wheels"
    folder.mkdir()
    (folder / CPU_WHEEL).write_bytes(b"")
    return folder


@pytest.fixture
def mixed_wheel_dir(wheel_dir):
    """A folder with the CPU wheel and two CUDA wheels of the pin (and an older CUDA one)."""
    for name in (*CUDA_WHEELS, "torch-2.12.0+cu129-cp311-cp311-manylinux_2_28_x86_64.whl"):
        (wheel_dir / name).write_bytes(b"")
    return wheel_dir


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
    # the wheel by its path (a folder with other builds beside it cannot swap it), the folder
    # for what it needs
    assert got.command == (*base, "--find-links", str(wheel_dir), str(wheel_dir / CPU_WHEEL), *TAIL)


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


def test_a_local_cuda_wheel_is_found_by_version_and_backend(mixed_wheel_dir):
    find = torch_build.local_wheel
    assert find(mixed_wheel_dir, "2.13.0", "cpu").name == CPU_WHEEL
    assert find(mixed_wheel_dir, "2.13.0", "cuda").name == CUDA_WHEELS[1]  # the newest CUDA
    assert find(mixed_wheel_dir, "2.13.0", "cu126").name == CUDA_WHEELS[0]
    assert find(mixed_wheel_dir, "2.13.0", "cu118") is None
    assert find(mixed_wheel_dir, "2.12.0", "cuda").name.startswith("torch-2.12.0+cu129-")
    assert torch_build.local_cpu_wheel(mixed_wheel_dir, "2.13.0").name == CPU_WHEEL
    with pytest.raises(ValueError, match="auto"):
        find(mixed_wheel_dir, "2.13.0", "auto")


@pytest.mark.parametrize("installer", ["uv", "pip"])
def test_torch_cuda_takes_a_local_cuda_wheel_where_one_is(mixed_wheel_dir, installer):
    """An offline GPU machine: the CUDA wheel from the folder (by its path), not an index."""
    wheel = torch_build.local_wheel(mixed_wheel_dir, "2.13.0", "cuda")
    got = _plan("cuda", installer, wheel=wheel)
    assert (got.build, got.source) == ("cuda", "local wheels")
    wheel_args = ("--find-links", str(mixed_wheel_dir), str(mixed_wheel_dir / CUDA_WHEELS[1]))
    assert got.command[-7:] == (*wheel_args, *TAIL)
    assert "--torch-backend" not in got.command and "--extra-index-url" not in got.command
    # a wheel of the other build is not installed for this one
    assert _plan("cpu", installer, wheel=wheel).source != "local wheels"


def test_the_plan_command_line_picks_the_wheel_of_the_build_asked(mixed_wheel_dir):
    """setup.sh's own call, printed instead of run: each TORCH gets its build's wheel."""

    def printed(asked: str) -> str:
        proc = subprocess.run(
            [sys.executable, str(ROOT / "tools" / "torch_build.py"), "plan", "--torch", asked,
             "--installer", "uv", "--python", PY, "--wheels", str(mixed_wheel_dir)],
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        return proc.stdout

    assert CPU_WHEEL in printed("cpu") and "+cu" not in printed("cpu")
    assert CUDA_WHEELS[1] in printed("cuda") and CPU_WHEEL not in printed("cuda")
    assert CUDA_WHEELS[0] in printed("cu126")


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


def test_without_torch_setup_keeps_the_build_it_remembered():
    """`make setup TORCH=cuda` then a plain `make run` (TORCH empty): the CUDA build stays;
    TORCH given again wins; a new environment is cpu, an older one keeps its installed build."""
    chosen = torch_build.chosen_torch
    assert chosen("", None) == "cpu"
    assert chosen(None, None, lambda: "cuda") == "cuda"  # set up before setup remembered
    assert chosen("", "cuda") == "cuda"
    assert chosen("  ", "cu126", lambda: "cpu") == "cu126"
    assert chosen("cpu", "cuda") == "cpu"
    assert chosen("CUDA", "cpu") == "cuda"
    assert chosen("", "nonsense") == "cpu"  # a damaged file is no choice
    with pytest.raises(ValueError, match="TORCH='gpu'"):
        chosen("gpu", "cuda")


def test_make_setup_torch_cuda_then_a_plain_make_run_keeps_cuda(tmp_path):
    """The whole chain without a download: the Makefile passes an empty TORCH when none is
    given; setup asks `chosen` (which reads what `remember` wrote after the CUDA install)."""
    make = subprocess.run(
        ["make", "-n", "-C", str(ROOT), "run", "VENV=" + str(tmp_path)],
        capture_output=True, text=True,
    )  # fmt: skip
    if make.returncode != 0 and "No such file" in make.stderr:
        pytest.skip("make is not installed")
    assert f"TORCH= bash tools/setup.sh {tmp_path}" in make.stdout, make.stdout
    explicit = subprocess.run(
        ["make", "-n", "-C", str(ROOT), "setup", "TORCH=cuda", "VENV=" + str(tmp_path)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert f"TORCH=cuda bash tools/setup.sh {tmp_path}" in explicit.stdout
    tool = [sys.executable, str(ROOT / "tools" / "torch_build.py")]

    def setup_would_use(torch: str) -> str:
        return subprocess.run(
            [*tool, "chosen", "--asked", torch, "--venv", str(tmp_path)],
            capture_output=True, text=True, check=True,
        ).stdout.strip()  # fmt: skip

    subprocess.run([*tool, "remember", "--venv", str(tmp_path), "cuda"], check=True)
    assert (tmp_path / torch_build.REMEMBERED).read_text().strip() == "cuda"
    assert setup_would_use("") == "cuda"  # the plain make run
    assert setup_would_use("cpu") == "cpu"  # TORCH given again


def test_setup_writes_no_tracked_file():
    """Setup's commands write only inside the virtual environment: no envs/*.yaml rewrite
    (the conda environments follow the config's device: tacgen_lib.runtime.conda_envs)."""
    script = (ROOT / "tools" / "setup.sh").read_text()
    assert "torch_build.py envs" not in script
    commands = set(re.findall(r'/bin/python" tools/torch_build\.py ([\w-]+)', script))
    assert commands == {"chosen", "build", "plan", "check", "gpu-check", "remember"}, commands


def _fake_torch(*, available=True, warn=None, fail=None, off=0.0):
    """A stand-in for the torch module's few calls the GPU check makes."""
    import torch

    def is_available():
        if warn:
            warnings.warn(warn, UserWarning, stacklevel=1)
        return available

    class Tensor:
        def __init__(self, value):
            self.value = value

        def to(self, device):
            if fail:
                raise RuntimeError(fail)
            return self

        def cpu(self):
            return Tensor(self.value + off)

        def __matmul__(self, other):
            return Tensor(self.value @ other.value)

        def __sub__(self, other):
            return self.value - other.value

    return SimpleNamespace(
        cuda=SimpleNamespace(is_available=is_available),
        Generator=torch.Generator,
        float64=torch.float64,
        randn=lambda *a, **k: Tensor(torch.randn(*a, **k)),
        allclose=lambda a, b, **k: torch.allclose(a.value, b.value, **k),
    )


def test_the_gpu_check_names_what_went_wrong():
    smoke = torch_build.gpu_smoke_error
    assert smoke(_fake_torch()) is None
    old = smoke(_fake_torch(available=False, warn="The NVIDIA driver on your system is too old"))
    assert "sees no usable GPU" in old and "driver on your system is too old" in old
    assert "no kernel image" in smoke(_fake_torch(fail="CUDA error: no kernel image"))
    assert "differs from the CPU's" in smoke(_fake_torch(off=1.0))
    message = torch_build.gpu_check_message("2.13.0+cu128", "12.8", "525.60.13", old)
    assert message is not None
    for part in ("2.13.0+cu128", "CUDA 12.8", "driver 525.60.13", "too old", "TORCH=cu"):
        assert part in message, part
    assert torch_build.gpu_check_message("2.13.0", "12.8", "550.54.14", None) is None
    note = torch_build.no_driver_note("2.13.0+cu128", "12.8")
    assert "not checked" in note and "12.8" in note


def test_the_driver_version_is_read_from_the_kernel_module(tmp_path):
    version = tmp_path / "version"
    version.write_text(
        "NVRM version: NVIDIA UNIX x86_64 Kernel Module  550.54.14  Thu Feb 22 01:44:30 UTC 2024\n"
        "GCC version:  gcc version 12.2.0 (Debian 12.2.0-14)\n"
    )
    assert torch_build.driver_version(version) == "550.54.14"
    open_module = tmp_path / "open"
    open_module.write_text(
        "NVRM version: NVIDIA UNIX Open Kernel Module for x86_64  560.35.03  Release Build\n"
    )
    assert torch_build.driver_version(open_module) == "560.35.03"
    assert torch_build.driver_version(tmp_path / "absent") is None


def test_gpu_check_passes_a_cpu_build_without_touching_a_gpu():
    """setup.sh runs gpu-check for every build: a CPU torch (this machine's) passes at once."""
    import torch

    if torch.version.cuda is not None:
        pytest.skip("torch here is a CUDA build")
    proc = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "torch_build.py"), "gpu-check"],
        capture_output=True, text=True, env={**os.environ, "CUDA_VISIBLE_DEVICES": ""},
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
