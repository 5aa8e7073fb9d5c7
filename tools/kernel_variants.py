"""Run the numeric tests again under other CPU kernels (`make test-kernels`, part of `make test`).

BLAS libraries and torch pick their kernels per CPU and per matrix shape, so a test that
demands bit identity between two different computations passes on one CPU and fails on
another. Choosing other kernels on this machine makes such a test fail here, where it is
written, instead of on a user's CPU. Each variant runs the tests that are not workflow runs
(`-m "not workflow and not slurm"`), less the modules and tests with no numerics a kernel could
round (`NOT_NUMERIC`, `NOT_NUMERIC_TESTS`), in a fresh process with some of these variables set:

- `OPENBLAS_CORETYPE`: the kernels of the OpenBLAS that numpy and SciPy bundle (threadpoolctl
  reports the choice as `architecture`).
- `MKL_ENABLE_INSTRUCTIONS`: the highest instruction set of the MKL that torch's CPU build
  uses for its BLAS (`torch.__config__.show()` names MKL; `MKL_VERBOSE=1` shows the calls but
  not the kernel). On AMD EPYC it changed no bit of an SGEMM (MKL takes its own path on a
  CPU that is not Intel's); on an Intel CPU it selects the kernels.
- `ONEDNN_MAX_CPU_ISA`: the oneDNN (mkldnn) kernels torch uses for convolutions, such as the
  ViT's patch embedding (SSE41 changes a conv2d's bits here; AVX2 gave AVX-512's bits).
- `ATEN_CPU_CAPABILITY`: torch's own vectorised kernels (`torch.backends.cpu
  .get_cpu_capability()`).
- `NPY_DISABLE_CPU_FEATURES`: numpy's SIMD dispatch targets (those this numpy build dispatches
  to and this CPU has; numpy refuses names it does not dispatch).
- threads: `--torch-threads` (tests/conftest.py) and `OMP_NUM_THREADS` / `OPENBLAS_NUM_THREADS`;
  how idle threads wait: `QUIET_WAITS`.

Before the tests, each variant's process reports the kernels it got (`active_kernels`), and
the tool stops if a variable did not take effect where this CPU allows the choice.

Ends with one line `kernels: N passed, N failed, N skipped` over all variants.

Usage: python tools/kernel_variants.py [--variant NAME ... | --all] [-- extra pytest args]
(without --variant: `default_variants` of this CPU, what `make test` runs)
Standard library only in this process; each variant's pytest imports the rest.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: numpy's AVX-512 dispatch targets (x86-64-v4 and later); those this build and CPU have are
#: disabled in the variants below
NUMPY_AVX512 = (
    "X86_V4",
    "AVX512F",
    "AVX512CD",
    "AVX512_SKX",
    "AVX512_CLX",
    "AVX512_CNL",
    "AVX512_ICL",
    "AVX512_SPR",
)

#: Test modules the variants leave out: none computes anything a BLAS, torch or numpy kernel
#: rounds (process mechanics, the config schema, the docs, the DAG's import closure).
NOT_NUMERIC = (
    "tests/runtime/test_preload.py",  # fork server mechanics (its own bit-identity check
    # compares one computation in two processes on the same kernels)
    "tests/io/test_code_inputs.py",
    "tests/io/test_config.py",
    "tests/io/test_settings.py",
    "tests/io/test_schema_settings.py",
    "tests/test_architecture.py",  # the import graph and module sizes, read from the source
    "tests/test_docs.py",
    "tests/runtime/test_scheduler.py",  # Snakemake's scheduler timers
    # its tests that are not workflow runs: config fuzzing, path and pickle refusals, and the
    # render-memory test (MuJoCo frames through Mesa: its RSS, not a float, is compared)
    "tests/test_faults.py",
    "tests/estimate/test_estimate.py",  # run-time estimates: sums of benchmark seconds
    "tests/test_kernel_variants.py",  # which variant a CPU class gets
    "tests/test_benchmarks.py",  # runs the benchmark scripts, whose figures are timings
    # which jobs ask for a GPU, and what: Snakemake's resources and sbatch arguments, read
    # from dry runs; which torch build setup installs; paper.yaml's DAG and time limits
    "tests/runtime/test_gpus.py",
    "tests/test_slurm_gpu.py",
    "tests/test_torch_build.py",
    "tests/test_paper_config.py",
)
#: single tests of numeric modules that compare no float: what a process imports, and which
#: checkpoint keys and shapes an architecture accepts
NOT_NUMERIC_TESTS = (
    "tests/test_optim.py::test_training_with_adamw_does_not_import_dynamo",
    "tests/features/test_backbone_families.py::test_mae_release_patch_of_16_needs_its_own_arch",
    "tests/test_device_check.py::test_the_run_mode_makes_one_copy_per_device",  # two dry runs
)

#: how a variant's idle threads wait. It runs beside the main suite, where a second thread
#: spinning after every parallel region (OpenMP's default spin, OpenBLAS's busy-wait) takes
#: the core the workflow runs need, and one put to sleep at once (OMP_WAIT_POLICY=PASSIVE)
#: costs a wake-up per region: OpenMP (torch) spins for a short count, OpenBLAS for its
#: shortest timeout (2**4 cycles), then both sleep
QUIET_WAITS = {"GOMP_SPINCOUNT": "10000", "OPENBLAS_THREAD_TIMEOUT": "4"}

#: name -> (environment, torch intra-op threads, what the variant stands for)
VARIANTS: dict[str, tuple[dict[str, str], int, str]] = {
    "avx2-2threads": (
        {
            "OPENBLAS_CORETYPE": "Haswell",
            "MKL_ENABLE_INSTRUCTIONS": "AVX2",
            "ONEDNN_MAX_CPU_ISA": "AVX2",
            "ATEN_CPU_CAPABILITY": "avx2",
            "NPY_DISABLE_CPU_FEATURES": "@avx512",
            "OMP_NUM_THREADS": "2",
            "OPENBLAS_NUM_THREADS": "2",
            **QUIET_WAITS,
        },
        2,
        "an EPYC without AVX-512 (every library on its AVX2 kernels), on two threads",
    ),
    "generic": (
        {
            "OPENBLAS_CORETYPE": "Sandybridge",
            "MKL_ENABLE_INSTRUCTIONS": "AVX",
            "ONEDNN_MAX_CPU_ISA": "SSE41",
            "ATEN_CPU_CAPABILITY": "default",
            "NPY_DISABLE_CPU_FEATURES": "@avx512",
            "OPENBLAS_NUM_THREADS": "2",  # the main run's BLAS has one (tests/conftest.py)
            **QUIET_WAITS,
        },
        1,
        "older kernels: AVX BLAS, SSE4.1 convolutions, torch's unvectorised default",
    ),
}
#: what `make test` runs, by this CPU's own torch capability (each variant re-runs every test
#: that is not a workflow run): a variant that picks kernels the machine does not use by
#: default. On a CPU with AVX-512 the AVX2 kernels are other kernels; on one without (AVX2 is
#: its own), AVX2 would repeat the main run, so it gets the older ones. The others on request
#: (`--variant NAME` or `--all`).
DEFAULT_VARIANTS = {"AVX512": ("avx2-2threads",), "AVX2": ("generic",), "DEFAULT": ("generic",)}


def native_capability() -> str:
    """This CPU's own torch kernel capability (``AVX512``, ``AVX2`` or ``DEFAULT``), asked of a
    process without any of the variants' variables."""
    names = {v for env, _, _ in VARIANTS.values() for v in env}
    env = {k: v for k, v in os.environ.items() if k not in names}
    code = "import torch; print(torch.backends.cpu.get_cpu_capability())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    if out.returncode != 0:
        raise RuntimeError(
            f"kernel_variants: cannot ask torch for this CPU's capability: {out.stderr}"
        )
    return out.stdout.strip().upper()


def default_variants(capability: str) -> tuple[str, ...]:
    """The variants `make test` runs on a CPU whose own torch capability is `capability`: the
    non-native ones (an unknown capability gets the oldest kernels)."""
    return DEFAULT_VARIANTS.get(capability, ("generic",))


def numpy_dispatch() -> list[str]:
    """The SIMD targets this process's numpy dispatches to (those its build has and the CPU,
    less NPY_DISABLE_CPU_FEATURES, allows)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # numpy < 2
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    return sorted(t for t in __cpu_dispatch__ if __cpu_features__.get(t))


def active_kernels() -> dict[str, object]:
    """The kernels this process's numpy, OpenBLAS, torch and MKL are using (imports them)."""
    import numpy as np
    import threadpoolctl
    import torch

    blas = [
        f"{p.get('internal_api')} {p.get('architecture', '?')} x{p.get('num_threads')}"
        for p in threadpoolctl.threadpool_info()
        if p.get("user_api") == "blas"
    ]
    return {
        "numpy": np.__version__,
        "numpy_dispatch": numpy_dispatch(),
        "openblas": blas,
        "torch": torch.__version__,
        "torch_capability": torch.backends.cpu.get_cpu_capability(),
        "torch_blas": "mkl" if "BLAS_INFO=mkl" in torch.__config__.show() else "other",
        "torch_threads": torch.get_num_threads(),
    }


def _numpy_avx512_targets() -> str:
    """The AVX-512 targets numpy dispatches to on this CPU, asked of a process without
    NPY_DISABLE_CPU_FEATURES (names numpy accepts in that variable)."""
    code = (
        f"import json, sys; sys.path.insert(0, {str(ROOT / 'tools')!r})\n"
        "from kernel_variants import numpy_dispatch\n"
        "print(json.dumps(numpy_dispatch()))"
    )
    env = {k: v for k, v in os.environ.items() if k != "NPY_DISABLE_CPU_FEATURES"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    if out.returncode != 0:
        return ""
    return " ".join(t for t in json.loads(out.stdout) if t in NUMPY_AVX512)


def _environment(name: str) -> dict[str, str]:
    env = {**os.environ, **VARIANTS[name][0]}
    if env.get("NPY_DISABLE_CPU_FEATURES") == "@avx512":
        targets = _numpy_avx512_targets()
        if targets:
            env["NPY_DISABLE_CPU_FEATURES"] = targets
        else:  # this CPU or numpy has no AVX-512 dispatch: nothing to disable
            env.pop("NPY_DISABLE_CPU_FEATURES")
    return env


def _check_took_effect(name: str, env: dict[str, str], got: dict[str, object]) -> list[str]:
    """Variables that did not change what they should, where this CPU offers the choice."""
    problems = []
    want_cap = env.get("ATEN_CPU_CAPABILITY", "").upper()
    native = {"AVX512": 3, "AVX2": 2, "DEFAULT": 0}
    if want_cap and got["torch_capability"] != want_cap:
        # torch falls back to what the CPU has: only a request below it must take effect
        if native.get(str(got["torch_capability"]), 9) > native.get(want_cap, 0):
            problems.append(f"ATEN_CPU_CAPABILITY={want_cap}: torch uses {got['torch_capability']}")
    core = env.get("OPENBLAS_CORETYPE")
    if core and got["openblas"] and not all(core in b for b in got["openblas"]):
        problems.append(f"OPENBLAS_CORETYPE={core}: OpenBLAS uses {got['openblas']}")
    disabled = env.get("NPY_DISABLE_CPU_FEATURES", "").split()
    still = [t for t in disabled if t in got["numpy_dispatch"]]
    if still:
        problems.append(f"NPY_DISABLE_CPU_FEATURES: numpy still dispatches to {still}")
    if got["torch_threads"] != VARIANTS[name][1]:
        problems.append(f"torch threads {got['torch_threads']}, wanted {VARIANTS[name][1]}")
    return problems


def _counts(junit: Path) -> tuple[int, int, int]:
    """(passed, failed, skipped) from a pytest JUnit XML report (failed counts errors too)."""
    import xml.etree.ElementTree as ET

    if not junit.exists():
        return 0, 0, 0
    root = ET.parse(junit).getroot()
    suites = [root] if root.tag == "testsuite" else list(root.iter("testsuite"))
    tests = sum(int(x.get("tests", 0)) for x in suites)
    failed = sum(int(x.get("failures", 0)) + int(x.get("errors", 0)) for x in suites)
    skipped = sum(int(x.get("skipped", 0)) for x in suites)
    return tests - failed - skipped, failed, skipped


def run_variant(name: str, pytest_args: list[str]) -> tuple[int, tuple[int, int, int]]:
    env = _environment(name)
    threads = VARIANTS[name][1]
    probe = (
        "import json, sys, torch\n"
        f"sys.path.insert(0, {str(ROOT / 'tools')!r})\n"
        f"torch.set_num_threads({threads})\n"
        "from kernel_variants import active_kernels\n"
        "print(json.dumps(active_kernels()))"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env)
    if out.returncode != 0:
        print(out.stderr, file=sys.stderr)
        return out.returncode, (0, 1, 0)
    got = json.loads(out.stdout)
    set_vars = {k: env[k] for k in sorted(VARIANTS[name][0]) if k in env}
    print(f"\n=== kernel variant {name}: {VARIANTS[name][2]}", flush=True)
    print(f"    set: {set_vars}", flush=True)
    print(f"    got: {got}", flush=True)
    problems = _check_took_effect(name, env, got)
    if problems:
        print(f"kernel variant {name}: a variable did not take effect: {problems}", file=sys.stderr)
        return 2, (0, 1, 0)
    # its own --basetemp: pytest prunes the numbered temporary directories of other sessions
    # (it keeps 3), which would pull a concurrent session's files from under it
    with tempfile.TemporaryDirectory(prefix=f"tacgen-kernels-{name}-") as tmp:
        junit = Path(tmp) / "junit.xml"
        cmd = [
            sys.executable,
            "-m",
            "pytest",
            "-m",
            "not workflow and not slurm",
            "-p",
            "no:cacheprovider",
            "-q",
            f"--torch-threads={threads}",
            f"--basetemp={tmp}/pytest",
            f"--junitxml={junit}",
            *(f"--ignore={m}" for m in NOT_NUMERIC),
            *(f"--deselect={t}" for t in NOT_NUMERIC_TESTS),
            *pytest_args,
        ]
        t0 = time.monotonic()
        rc = subprocess.run(cmd, cwd=ROOT, env=env).returncode
        counts = _counts(junit)
    print(f"=== kernel variant {name}: exit {rc} in {time.monotonic() - t0:.0f} s", flush=True)
    return rc, counts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variant", action="append", choices=list(VARIANTS))
    parser.add_argument("--all", action="store_true", help="every variant")
    args, rest = parser.parse_known_args(argv)
    rest = [a for a in rest if a != "--"]
    failed, total = [], [0, 0, 0]
    if args.all:
        names = list(VARIANTS)
    elif args.variant:
        names = args.variant
    else:
        capability = native_capability()
        names = list(default_variants(capability))
        print(f"kernel variants: this CPU's own kernels are {capability}; running {names}")
    for name in names:
        rc, counts = run_variant(name, rest)
        total = [a + b for a, b in zip(total, counts, strict=True)]
        if rc != 0:
            failed.append(name)
    if failed:
        print(f"kernel variants failed: {failed}", file=sys.stderr)
    # one closing line for all variants, in the form test runners close with
    print(f"kernels: {total[0]} passed, {total[1]} failed, {total[2]} skipped", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
