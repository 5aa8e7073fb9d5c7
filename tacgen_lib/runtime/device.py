"""Where a torch job computes: the config key `device` (cpu | cuda | auto).

Every torch job of the workflow (backbone pretraining, feature extraction, alignment heads, the
latent generator's training and sampling, the pixel generators, the policy) takes the config's
`device` through its rule's params and calls `torch_device` once. What each value promises
(README, "CPU or GPU"; docs/cluster.md):

- ``cpu`` (the default): the computation of a CPU-only run, bit for bit. Models are built and
  every random draw is made on the CPU (seeded torch and numpy generators), then moved to the
  device: on the CPU that move is no move at all, so the edges are the same bytes as before the
  key existed.
- ``cuda``: the first CUDA GPU; a run stops, saying so, where torch has no CUDA or sees no GPU.
  The random draws are the CPU's (the same numbers as on the CPU), the arithmetic the GPU's:
  results agree with the CPU's within float tolerance, and two runs on the same GPU with the
  same seeds agree within tolerance, not bit for bit (cuBLAS and cuDNN choose kernels and
  reduction orders at run time; `torch_device` turns off cuDNN's autotuner and asks for its
  deterministic kernels, which narrows but does not remove the differences).
- ``auto``: cuda where torch sees a GPU, else cpu.

Imports torch only when called (the preloaded interpreter's modules import this one).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch

__all__ = ["DEVICES", "cuda_unavailable", "torch_device"]

#: The config key's values (config/config.schema.yaml `device`).
DEVICES = ("cpu", "cuda", "auto")


def cuda_unavailable() -> str | None:
    """Why no CUDA GPU can be used here (None where one can): torch built without CUDA, or no
    GPU visible to it."""
    import torch

    if torch.version.cuda is None:
        return f"torch {torch.__version__} is built without CUDA (make run TORCH=cuda installs one)"
    if not torch.cuda.is_available():
        return f"torch {torch.__version__} (CUDA {torch.version.cuda}) sees no GPU"
    return None


def torch_device(name: str) -> torch.device:
    """The torch device of the config value `name` (`DEVICES`). ``cuda`` where no GPU can be
    used stops with the reason; ``auto`` falls back to the CPU there. On a GPU, cuDNN's
    autotuner is turned off, its deterministic kernels asked for, and cuBLAS given its
    deterministic workspace (CUBLAS_WORKSPACE_CONFIG, unless set)."""
    import torch

    if name not in DEVICES:
        raise ValueError(f"device {name!r}: expected one of {', '.join(DEVICES)}")
    if name == "cpu":
        return torch.device("cpu")
    why = cuda_unavailable()
    if why is not None:
        if name == "auto":
            return torch.device("cpu")
        raise RuntimeError(f"config device: cuda, but {why}; set device: cpu (or auto)")
    # cuBLAS's deterministic workspace (read when its first handle is made: before any work)
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.backends.cudnn.benchmark = False
    torch.backends.cudnn.deterministic = True
    return torch.device("cuda")
