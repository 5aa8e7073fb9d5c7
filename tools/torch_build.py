"""Which torch build `tools/setup.sh` installs, from where, and whether the one installed is it.

The decision is a pure function of what the user asked for (`TORCH`), what the machine has (a
local CPU wheel folder, an NVIDIA driver, what torch is installed already) and which installer
runs (uv or pip): `plan` returns the installer's command, and setup.sh runs it. The command is
tested without a network (tests/test_torch_build.py).

    TORCH=cpu    (the default) the CPU build: from a local wheel folder where it holds torch's CPU wheel
                 (`--find-links`, as this repository's CI machines have in /opt/wheels), else
                 from PyTorch's CPU wheel index (uv `--torch-backend cpu`; pip
                 `--extra-index-url https://download.pytorch.org/whl/cpu`). Never PyPI's torch,
                 which on Linux x86_64 is the CUDA build (torch, triton and ~16 nvidia-* packages).
    TORCH=cuda   a CUDA build: uv `--torch-backend auto` (uv picks the CUDA index that matches
                 the driver); pip takes PyPI's torch, which is the CUDA build.
    TORCH=cu126  (any uv backend name cuNNN) that CUDA index exactly.
    TORCH=auto   cuda where an NVIDIA driver is loaded (/proc/driver/nvidia/version),
                 else cpu.

The conda environment files (envs/*.yaml, for `--sdm conda`) name the same build: conda-forge's
`pytorch-cpu` or `pytorch-gpu` metapackage (`conda_line`). setup.sh writes the build it installs
into their torch line (`python tools/torch_build.py envs cuda`; `... envs cpu` restores them), so
`--sdm conda` builds its environments with the same build.

Command line (setup.sh's):
    .venv/bin/python tools/torch_build.py plan --torch auto --installer uv --python .venv/bin/python
    .venv/bin/python tools/torch_build.py build         # the installed torch's build: cpu, cuda
    .venv/bin/python tools/torch_build.py check --asked cpu   # exit 1 naming both if it differs
    python3 tools/torch_build.py envs cuda
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Where this repository's machines keep torch's CPU wheel (CI relies on it).
LOCAL_WHEELS = Path("/opt/wheels")
#: PyTorch's own CPU wheel index (pip's form of uv's `--torch-backend cpu`).
CPU_INDEX = "https://download.pytorch.org/whl/cpu"
#: What the NVIDIA kernel driver shows where it is loaded.
NVIDIA_DRIVER = Path("/proc/driver/nvidia/version")
#: The torch version constraints.txt pins (read from it; `torch_pin`).
CONSTRAINTS = ROOT / "constraints.txt"
ENVS = ROOT / "envs"
#: conda-forge's metapackages for each build (envs/*.yaml).
CONDA_PACKAGES = {"cpu": "pytorch-cpu", "cuda": "pytorch-gpu"}

_CUDA_BACKEND = re.compile(r"^cu\d{2,3}$")


@dataclass(frozen=True)
class TorchPlan:
    """What setup.sh installs: the `build` ("cpu" or "cuda") it asks for, where torch comes
    from (`source`: "local wheels", "pytorch cpu index", "pytorch cuda index", "pypi"), the
    installer's `command`, and `uninstall`: the command that removes an installed torch of the
    other build first (empty where there is none: the pin would be met by it and kept)."""

    build: str
    source: str
    command: tuple[str, ...]
    uninstall: tuple[str, ...] = ()

    def describe(self) -> str:
        return f"torch {self.build} build from {self.source}"


def torch_pin(constraints: Path = CONSTRAINTS) -> str:
    """The version constraints.txt pins torch to (`torch==X.Y.Z`)."""
    for line in constraints.read_text().splitlines():
        m = re.match(r"^\s*torch\s*==\s*([^\s#;]+)", line)
        if m:
            return m.group(1)
    raise ValueError(f"{constraints}: no torch==<version> line")


def local_cpu_wheel(folder: Path, version: str) -> Path | None:
    """torch's CPU wheel of `version` in `folder` (`torch-<version>+cpu-*.whl`), if there is one."""
    if not folder.is_dir():
        return None
    found = sorted(folder.glob(f"torch-{version}+cpu-*.whl"))
    return found[0] if found else None


def resolve_build(asked: str, *, nvidia_driver: bool) -> str:
    """The build a `TORCH` value asks for: cpu, cuda (also for a cuNNN backend), or for auto
    cuda where an NVIDIA driver is loaded, else cpu."""
    asked = asked.strip().lower()
    if asked == "cpu":
        return "cpu"
    if asked == "cuda" or _CUDA_BACKEND.match(asked):
        return "cuda"
    if asked == "auto":
        return "cuda" if nvidia_driver else "cpu"
    raise ValueError(f"TORCH={asked!r}: expected cpu, cuda, auto or a CUDA backend such as cu126")


def plan(
    asked: str,
    *,
    installer: str,
    python: str,
    version: str,
    local_wheel: Path | None,
    nvidia_driver: bool,
    installed: str | None = None,
    constraints: str = "constraints.txt",
    target: str = ".[workflow,dev]",
    uv: str = "uv",
) -> TorchPlan:
    """The install command for `TORCH=asked`: `installer` "uv" (its `pip install`) or "pip",
    into the interpreter `python` (uv: the executable `uv`), the project `target` editable
    under `constraints` (which pins torch to `version`). `local_wheel`: torch's CPU wheel in a local folder (or None);
    `nvidia_driver`: whether one is loaded; `installed`: the build of the torch installed now
    (`build_of`; None where there is none): replaced where it is not the one asked for."""
    if installer not in ("uv", "pip"):
        raise ValueError(f"installer {installer!r}: expected uv or pip")
    build = resolve_build(asked, nvidia_driver=nvidia_driver)
    backend = asked.strip().lower()
    if installer == "uv":
        base = [uv, "pip", "install", "-q", "--python", python, "--compile-bytecode"]
    else:
        base = [python, "-m", "pip", "install", "-q"]
    torch_args: list[str]
    if build == "cpu" and local_wheel is not None:
        source, torch_args = "local wheels", ["--find-links", str(local_wheel.parent)]
    elif build == "cpu":
        source = "pytorch cpu index"
        torch_args = (
            ["--torch-backend", "cpu"] if installer == "uv" else ["--extra-index-url", CPU_INDEX]
        )
    elif installer == "uv":
        source = "pytorch cuda index"
        torch_args = ["--torch-backend", backend if _CUDA_BACKEND.match(backend) else "auto"]
    elif _CUDA_BACKEND.match(backend):
        source = "pytorch cuda index"
        torch_args = ["--extra-index-url", f"https://download.pytorch.org/whl/{backend}"]
    else:
        source, torch_args = "pypi", []  # PyPI's Linux x86_64 torch is the CUDA build
    uninstall: tuple[str, ...] = ()
    if installed is not None and installed != build:
        # the pin (torch==X.Y.Z) is met by the other build too: remove it, so the one asked
        # for is installed
        if installer == "uv":
            uninstall = (uv, "pip", "uninstall", "-q", "--python", python, "torch")
        else:
            uninstall = (python, "-m", "pip", "uninstall", "-q", "-y", "torch")
    command = [*base, *torch_args, "-c", constraints, "-e", target]
    return TorchPlan(build=build, source=source, command=tuple(command), uninstall=uninstall)


def build_of(version: str, cuda: str | None) -> str:
    """The build of an installed torch `version` (`torch.__version__`) built with CUDA `cuda`
    (`torch.version.cuda`, None without): its local label where it has one (cpu, cu126 ...:
    cuda), else cuda where built with CUDA (PyPI's Linux wheel), else cpu."""
    label = version.partition("+")[2]
    if label == "cpu":
        return "cpu"
    if label.startswith("cu") or (not label and cuda is not None):
        return "cuda"
    return label or "cpu"


def check_build(version: str, cuda: str | None, asked: str, *, nvidia_driver: bool) -> str | None:
    """None where torch `version` (built with CUDA `cuda`, None without) is the build that
    `TORCH=asked` asks for; else the message setup stops with, naming both."""
    want = resolve_build(asked, nvidia_driver=nvidia_driver)
    found = build_of(version, cuda)
    if found == want:
        return None
    return (
        f"setup: torch {version} is the {found} build, but TORCH={asked} asks for the {want} "
        f"build (tools/torch_build.py); run setup again with TORCH={want}"
    )


def conda_line(build: str) -> str:
    """The envs/*.yaml dependency line of the torch build (conda-forge's metapackage)."""
    return (
        f"  - {CONDA_PACKAGES[build]}=2.*   # {build} build, as setup's TORCH: tools/torch_build.py"
    )


def conda_env_text(text: str, build: str) -> str:
    """An envs/*.yaml file's text with its torch line naming `build` (exactly one such line)."""
    pattern = re.compile(r"^  - pytorch-(?:cpu|gpu)=.*$", re.MULTILINE)
    if len(pattern.findall(text)) != 1:
        raise ValueError("expected one '  - pytorch-cpu=...' or '  - pytorch-gpu=...' line")
    return pattern.sub(conda_line(build), text)


def _main(argv: Sequence[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    p = sub.add_parser(
        "plan", help="print (or --run) the commands that install the torch build asked for"
    )
    p.add_argument("--torch", default="cpu")
    p.add_argument("--installer", choices=("uv", "pip"), required=True)
    p.add_argument("--python", required=True)
    p.add_argument("--installed", default="", help="the build installed now (`build`), if any")
    p.add_argument("--uv", default="uv", help="uv's executable")
    p.add_argument("--run", action="store_true", help="run the commands (else print them)")
    p.add_argument("--wheels", default=os.environ.get("TACGEN_WHEELS", str(LOCAL_WHEELS)))
    sub.add_parser("build", help="print the installed torch's build (cpu, cuda), or nothing")
    c = sub.add_parser("check", help="exit 1 naming both builds if torch is not the one asked")
    c.add_argument("--asked", default="cpu")
    e = sub.add_parser("envs", help="rewrite the torch line of envs/*.yaml for a TORCH value")
    e.add_argument("torch", help="cpu, cuda, cuNNN or auto")
    args = parser.parse_args(argv)
    driver = NVIDIA_DRIVER.exists()
    if args.what == "plan":
        version = torch_pin()
        chosen = plan(
            args.torch,
            installer=args.installer,
            python=args.python,
            version=version,
            local_wheel=local_cpu_wheel(Path(args.wheels), version),
            nvidia_driver=driver,
            installed=args.installed or None,
            uv=args.uv,
        )
        print(f"setup: {chosen.describe()}", file=sys.stderr)
        for command in (chosen.uninstall, chosen.command):
            if not command:
                continue
            if not args.run:
                print(shlex.join(command))
            elif subprocess.run(command, cwd=ROOT).returncode != 0:
                print(f"setup: failed: {shlex.join(command)}", file=sys.stderr)
                return 1
        return 0
    if args.what == "build":
        try:
            import torch
        except ImportError:
            return 0
        print(build_of(torch.__version__, torch.version.cuda))
        return 0
    if args.what == "check":
        import torch

        message = check_build(
            torch.__version__, torch.version.cuda, args.asked, nvidia_driver=driver
        )
        if message:
            print(message, file=sys.stderr)
            return 1
        return 0
    build = resolve_build(args.torch, nvidia_driver=driver)
    for path in sorted(ENVS.glob("*.yaml")):
        text = path.read_text()
        if conda_env_text(text, build) != text:
            path.write_text(conda_env_text(text, build))
            print(f"setup: {path.relative_to(ROOT)} names torch's {build} build", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
