"""The kernel variant `make test` runs picks kernels this CPU does not use by default, on every
CPU class (tools/kernel_variants.py)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import kernel_variants  # noqa: E402

#: torch's kernel capabilities, lowest first
RANK = {"DEFAULT": 0, "AVX2": 1, "AVX512": 2}


@pytest.mark.parametrize("capability", sorted(RANK))
def test_every_default_variant_runs_kernels_below_the_cpus_own(capability: str) -> None:
    chosen = kernel_variants.default_variants(capability)
    assert chosen, capability
    for name in chosen:
        wanted = kernel_variants.VARIANTS[name][0]["ATEN_CPU_CAPABILITY"].upper()
        below_native = RANK[wanted] < RANK[capability]
        # on a CPU with no vector kernels of its own the variant still changes OpenBLAS's
        # core type and oneDNN's instruction set
        assert below_native or capability == "DEFAULT", (capability, name, wanted)
        assert "OPENBLAS_CORETYPE" in kernel_variants.VARIANTS[name][0]


def test_an_unknown_capability_gets_the_oldest_kernels() -> None:
    assert kernel_variants.default_variants("SVE256") == ("generic",)


def test_the_native_capability_is_what_torch_reports_without_the_variables() -> None:
    native = kernel_variants.native_capability()
    assert native in RANK
    if "ATEN_CPU_CAPABILITY" not in os.environ:
        import torch

        assert native == torch.backends.cpu.get_cpu_capability().upper()
