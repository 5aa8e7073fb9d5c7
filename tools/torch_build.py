"""Which torch build `tools/setup.sh` installs, from where, and whether the one installed works.

The decision is a pure function of what the user asked for (`TORCH`, or the build setup
remembered), what the machine has (a local wheel folder, an NVIDIA driver, what torch is
installed already) and which installer runs (uv or pip): `plan` returns the installer's
command, and setup.sh runs it. The command is tested without a network
(tests/test_torch_build.py).

    TORCH unset  the build setup last installed into this environment (`chosen_torch`: it is
                 remembered in <venv>/.tacgen-torch until TORCH is given again), cpu for a
                 new one. So `make setup TORCH=cuda` then a plain `make run` keeps CUDA.
    TORCH=cpu    the CPU build: from a local wheel folder where it holds torch's CPU wheel
                 (as this repository's CI machines have in /opt/wheels), else from PyTorch's
                 CPU wheel index (uv `--torch-backend cpu`; pip
                 `--extra-index-url https://download.pytorch.org/whl/cpu`). Never PyPI's torch,
                 which on Linux x86_64 is the CUDA build (torch, triton and ~16 nvidia-* packages).
    TORCH=cuda   a CUDA build: from a local wheel folder where it holds a CUDA wheel of the pin
                 (`+cuNNN`, the newest), else uv `--torch-backend auto` (uv picks the CUDA
                 index that matches the driver); pip takes PyPI's torch, the CUDA build.
    TORCH=cu126  (any uv backend name cuNNN) that CUDA build exactly, from a local `+cu126`
                 wheel or that CUDA index.
    TORCH=auto   cuda where an NVIDIA driver is loaded (/proc/driver/nvidia/version),
                 else cpu.

A local wheel is installed by its path (the folder also given as `--find-links`, so the CUDA
libraries it needs can sit beside it on an offline machine). After installing, setup checks
the build (`check`) and, for a CUDA build, runs a small computation on the GPU against the
CPU (`gpu-check`): a driver too old for the wheel stops setup there, naming both. Setup
writes no tracked file: the conda environments (envs/*.yaml, `--sdm conda`) follow the
config's `device` instead (tacgen_lib.runtime.conda_envs).

Command line (setup.sh's):
    .venv/bin/python tools/torch_build.py chosen --asked "$TORCH" --venv .venv   # the TORCH to use
    .venv/bin/python tools/torch_build.py plan --torch auto --installer uv --python .venv/bin/python
    .venv/bin/python tools/torch_build.py build         # the installed torch's build: cpu, cuda
    .venv/bin/python tools/torch_build.py check --asked cpu   # exit 1 naming both if it differs
    .venv/bin/python tools/torch_build.py gpu-check     # a CUDA build computes on the GPU
    .venv/bin/python tools/torch_build.py remember --venv .venv cuda
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Where this repository's machines keep torch's wheels (CI relies on its CPU wheel).
LOCAL_WHEELS = Path("/opt/wheels")
#: The file in a virtual environment that remembers the TORCH its build was installed for.
REMEMBERED = ".tacgen-torch"
#: PyTorch's own CPU wheel index (pip's form of uv's `--torch-backend cpu`).
CPU_INDEX = "https://download.pytorch.org/whl/cpu"
#: What the NVIDIA kernel driver shows where it is loaded.
NVIDIA_DRIVER = Path("/proc/driver/nvidia/version")
#: The torch version constraints.txt pins (read from it; `torch_pin`).
CONSTRAINTS = ROOT / "constraints.txt"
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


def local_wheel(folder: Path, version: str, build: str = "cpu") -> Path | None:
    """torch's wheel of `version` in `folder` for `build`, if there is one: cpu
    ``torch-<version>+cpu-*.whl``, a backend cuNNN ``+cuNNN``, cuda the newest CUDA wheel
    there (``+cu128`` before ``+cu126``). `build` is resolved: not auto."""
    if not folder.is_dir():
        return None
    build = build.strip().lower()
    if build == "cpu" or _CUDA_BACKEND.match(build):
        found = sorted(folder.glob(f"torch-{version}+{build}-*.whl"))
        return found[0] if found else None
    if build != "cuda":
        raise ValueError(f"local wheel of build {build!r}: expected cpu, cuda or cuNNN")
    cuda = [p for p in folder.glob(f"torch-{version}+cu*-*.whl") if _wheel_cuda(p) is not None]
    return max(cuda, key=lambda p: (_wheel_cuda(p), p.name)) if cuda else None


def _wheel_cuda(path: Path) -> int | None:
    """The CUDA version number of a ``torch-X+cuNNN-...whl`` name (126), else None."""
    m = re.match(r"^torch-[^+]+\+cu(\d{2,3})-", path.name)
    return int(m.group(1)) if m else None


def local_cpu_wheel(folder: Path, version: str) -> Path | None:
    """torch's CPU wheel of `version` in `folder` (`torch-<version>+cpu-*.whl`), if there is one."""
    return local_wheel(folder, version, "cpu")


def chosen_torch(
    asked: str | None, remembered: str | None, installed: Callable[[], str | None] = lambda: None
) -> str:
    """The TORCH value setup installs for: `asked` where given (non-empty); else the value
    setup `remembered` from its last install into this environment; else the build of the
    torch `installed()` there (an environment set up before setup remembered it); else cpu.
    An unknown asked value is refused (`resolve_build`), a remembered one ignored."""
    if asked is not None and asked.strip():
        resolve_build(asked, nvidia_driver=False)  # refuses an unknown value
        return asked.strip().lower()
    if remembered is not None and remembered.strip():
        try:
            resolve_build(remembered, nvidia_driver=False)
            return remembered.strip().lower()
        except ValueError:
            pass
    return installed() or "cpu"


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
    under `constraints` (which pins torch to `version`). `local_wheel`: torch's wheel of the
    build asked for in a local folder (`local_wheel`; or None; another build's is ignored),
    installed by its path;
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
    if local_wheel is not None and build_of(local_wheel.name.split("-")[1], None) != build:
        local_wheel = None  # another build's wheel: not this one's source
    if local_wheel is not None:
        source = "local wheels"
        torch_args = ["--find-links", str(local_wheel.parent), str(local_wheel)]
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


def driver_version(path: Path = NVIDIA_DRIVER) -> str | None:
    """The loaded NVIDIA kernel driver's version ("550.54.14"), None where none is loaded."""
    try:
        text = path.read_text()
    except OSError:
        return None
    m = re.search(r"Kernel Module(?: for \S+)?\s+(\d+(?:\.\d+)+)", text)
    return m.group(1) if m else "unknown"


def gpu_check_message(version: str, cuda: str | None, driver: str, error: str | None) -> str | None:
    """What setup stops with after running a small computation on the GPU with torch
    `version` (built for CUDA `cuda`) under NVIDIA driver `driver`: None where it ran and
    matched the CPU (`error` None); else a message naming the wheel's CUDA, the driver and
    torch's own error."""
    if error is None:
        return None
    return (
        f"setup: torch {version} (built for CUDA {cuda}) cannot compute on the GPU under "
        f"NVIDIA driver {driver}: {error}. A driver older than the wheel's CUDA needs a newer "
        f"driver or an older CUDA build (TORCH=cu118 ...; tools/torch_build.py)"
    )


def no_driver_note(version: str, cuda: str | None) -> str:
    """What setup says for a CUDA build where no NVIDIA driver is loaded (a cluster's login
    node): installed, not checked on a GPU."""
    return (
        f"setup: note: torch {version} is a CUDA {cuda} build; no NVIDIA driver is loaded here, "
        "so it is not checked on a GPU: run setup again on a GPU machine to check it"
    )


def gpu_smoke_error(torch) -> str | None:  # noqa: ANN001 - the torch module
    """Run a small matrix product on the first GPU and on the CPU; None where the GPU ran it
    and agreed within float tolerance, else what went wrong (torch's own words)."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if not torch.cuda.is_available():
                said = (
                    "; ".join(str(w.message) for w in caught)
                    or "torch.cuda.is_available() is False"
                )
                return f"torch sees no usable GPU ({said})"
            g = torch.Generator().manual_seed(0)
            a = torch.randn(256, 256, generator=g, dtype=torch.float64)
            want = a @ a
            got = (a.to("cuda") @ a.to("cuda")).cpu()
        except Exception as exc:  # noqa: BLE001 - any failure is the message
            return f"{type(exc).__name__}: {exc}".strip()
    if not torch.allclose(got, want, rtol=1e-9, atol=1e-9):
        worst = float((got - want).abs().max())
        return f"the GPU's 256 x 256 product differs from the CPU's by up to {worst:.3g}"
    return None


def remembered_torch(venv: Path) -> str | None:
    """The TORCH value setup last installed into `venv` for, if it wrote one."""
    try:
        return (venv / REMEMBERED).read_text().strip() or None
    except OSError:
        return None


def _installed_build() -> str | None:
    """The build of the torch this interpreter imports (`build_of`), None without one."""
    try:
        import torch
    except ImportError:
        return None
    return build_of(torch.__version__, torch.version.cuda)


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
    sub.add_parser("gpu-check", help="a CUDA build: exit 1 unless a GPU computes a product")
    ch = sub.add_parser("chosen", help="print the TORCH to install: asked, else remembered")
    ch.add_argument("--asked", default="")
    ch.add_argument("--venv", required=True)
    r = sub.add_parser("remember", help="remember the TORCH a venv's build was installed for")
    r.add_argument("--venv", required=True)
    r.add_argument("torch")
    args = parser.parse_args(argv)
    driver = NVIDIA_DRIVER.exists()
    if args.what == "chosen":
        print(chosen_torch(args.asked, remembered_torch(Path(args.venv)), _installed_build))
        return 0
    if args.what == "remember":
        (Path(args.venv) / REMEMBERED).write_text(chosen_torch(args.torch, None) + "\n")
        return 0
    if args.what == "plan":
        version = torch_pin()
        build = resolve_build(args.torch, nvidia_driver=driver)
        exact = args.torch.strip().lower()
        chosen = plan(
            args.torch,
            installer=args.installer,
            python=args.python,
            version=version,
            local_wheel=local_wheel(
                Path(args.wheels), version, exact if _CUDA_BACKEND.match(exact) else build
            ),
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
        print(_installed_build() or "")
        return 0
    import torch

    if args.what == "check":
        message = check_build(
            torch.__version__, torch.version.cuda, args.asked, nvidia_driver=driver
        )
    else:  # gpu-check
        if torch.version.cuda is None:
            return 0
        found = driver_version()
        if found is None:
            print(no_driver_note(torch.__version__, torch.version.cuda), file=sys.stderr)
            return 0
        message = gpu_check_message(
            torch.__version__, torch.version.cuda, found, gpu_smoke_error(torch)
        )
    if message:
        print(message, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
