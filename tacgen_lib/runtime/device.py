"""Where a torch job computes: the config key `device` (cpu | cuda | auto), with `allow_tf32`.

Every torch job of the workflow (backbone pretraining, feature extraction, alignment heads, the
latent generator's training and sampling, the regime's generators, the pixel generators, the
policy) takes the run's device spec through its rule's params (`device_spec`: the config's
`device`, with ``+tf32`` where config `allow_tf32` lets a GPU use TF32) and calls
`torch_device` once. What each value promises (README, "CPU or GPU"; docs/cluster.md):

- ``cpu`` (the default): the computation of a CPU-only run, bit for bit. Models are built and
  every random draw is made on the CPU (seeded torch and numpy generators), then moved to the
  device: on the CPU that move is no move at all, so the edges are the same bytes as before the
  key existed.
- ``cuda``: a CUDA GPU; a run stops, saying so, where torch has no CUDA or sees no GPU.
  The random draws are the CPU's (the same numbers as on the CPU), the arithmetic the GPU's:
  results agree with the CPU's within float tolerance, and two runs on the same GPU with the
  same seeds agree within tolerance, not bit for bit (cuBLAS and cuDNN choose kernels and
  reduction orders at run time; `torch_device` turns off cuDNN's autotuner and asks for its
  deterministic kernels, which narrows but does not remove the differences). Float32 matrix
  products and convolutions are computed in float32: TF32 (a 10-bit mantissa on Ampere and
  later GPUs, which cuDNN's convolutions use by default) is off unless config `allow_tf32`.
  Where a job sees several GPUs, it takes one no other job holds
  (`tacgen_lib.runtime.gpus.claim_gpu`) before CUDA is first touched.
- ``auto``: cuda where torch sees a GPU, else cpu (refused on a cluster executor:
  `tacgen_lib.runtime.gpus.run_uses_gpu`).

Imports torch only when called (the preloaded interpreter's modules import this one).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from tacgen_lib.runtime.gpus import claim_gpu, visible_gpus

if TYPE_CHECKING:
    import torch

__all__ = [
    "DEVICES",
    "configure_cuda_math",
    "cuda_unavailable",
    "device_spec",
    "parse_device_spec",
    "torch_device",
]

#: The config key's values (config/config.schema.yaml `device`).
DEVICES = ("cpu", "cuda", "auto")
#: the suffix of a device spec whose GPU may use TF32 (config allow_tf32)
TF32 = "+tf32"


def device_spec(device: str, allow_tf32: bool) -> str:
    """The device spec a torch rule passes in its params: the config's `device`, with
    ``+tf32`` where `allow_tf32` and the device can be a GPU. ``cpu`` stays ``cpu`` whatever
    `allow_tf32` says (TF32 is a GPU format), so a CPU run's params never change with it."""
    if device not in DEVICES:
        raise ValueError(f"device {device!r}: expected one of {', '.join(DEVICES)}")
    return device + TF32 if allow_tf32 and device != "cpu" else device


def parse_device_spec(spec: str) -> tuple[str, bool]:
    """(device, allow_tf32) of a spec `device_spec` made; an unknown device is refused."""
    name, plus, option = spec.partition("+")
    if name not in DEVICES or (plus and plus + option != TF32):
        raise ValueError(
            f"device {spec!r}: expected one of {', '.join(DEVICES)} (optionally with {TF32})"
        )
    return name, bool(plus)


def cuda_unavailable() -> str | None:
    """Why no CUDA GPU can be used here (None where one can): torch built without CUDA, or no
    GPU visible to it."""
    import torch

    if torch.version.cuda is None:
        return (
            f"torch {torch.__version__} is built without CUDA (make setup TORCH=cuda installs one)"
        )
    if not torch.cuda.is_available():
        return f"torch {torch.__version__} (CUDA {torch.version.cuda}) sees no GPU"
    return None


def configure_cuda_math(allow_tf32: bool) -> None:
    """The GPU arithmetic a job runs with: cuDNN's autotuner off and its deterministic
    kernels asked for; TF32 in cuBLAS matrix products and cuDNN convolutions only where
    `allow_tf32`. Set through torch's `allow_tf32` flags for both (torch refuses a mix of
    those with its `fp32_precision` settings); process-wide, and harmless on a CPU build."""
    import torch

    torch.backends.cudnn.benchmark = False
    torch.backends.cudnn.deterministic = True
    torch.backends.cuda.matmul.allow_tf32 = bool(allow_tf32)
    torch.backends.cudnn.allow_tf32 = bool(allow_tf32)


def torch_device(spec: str) -> torch.device:
    """The torch device of the device spec `spec` (`device_spec`; a bare `DEVICES` value).
    ``cuda`` where no GPU can be used stops with the reason; ``auto`` falls back to the CPU
    there. On a GPU: where the job sees several, it takes one no other job holds
    (CUDA_VISIBLE_DEVICES narrowed to it, before CUDA is first touched); cuBLAS is given its
    deterministic workspace (CUBLAS_WORKSPACE_CONFIG, unless set) and `configure_cuda_math`
    sets the arithmetic."""
    import torch

    name, allow_tf32 = parse_device_spec(spec)
    if name == "cpu":
        return torch.device("cpu")
    if torch.version.cuda is not None:
        gpu = claim_gpu(visible_gpus())
        if gpu is not None:
            os.environ["CUDA_VISIBLE_DEVICES"] = gpu
    why = cuda_unavailable()
    if why is not None:
        if name == "auto":
            return torch.device("cpu")
        raise RuntimeError(f"config device: cuda, but {why}; set device: cpu (or auto)")
    # cuBLAS's deterministic workspace (read when its first handle is made: before any work)
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    configure_cuda_math(allow_tf32)
    return torch.device("cuda")
