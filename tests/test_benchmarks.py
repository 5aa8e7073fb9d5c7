"""Every script in benchmarks/ runs to its end in its tiny mode and prints finite figures.

Nothing else runs the benchmarks, so a library change that breaks one would go unnoticed until
someone measures with it (docs/cost.md, "Speed: the benchmarks"). Here each script runs as a
user runs it, `python benchmarks/<script>.py` in its own interpreter, with `TINY_ENV` set
(benchmarks/machine.py: the smallest sizes, in seconds), two at a time. A script fails on a
non-zero exit, on a printed figure that is not finite (nan, inf), on printing no figure, and
on not saying it ran tiny (a script that ignores the mode would run at full size).

The scripts that read a finished run (`RUN_ARGS`) read the session's shared run of
config/test.yaml (`reference_run`, which no test changes); the others need no run, so
``-k "not finished_run"`` checks them without building one.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest
from snakemake_run import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
from machine import TINY_ENV  # noqa: E402  (benchmarks/ is a folder of scripts)

SCRIPTS = sorted(p.name for p in (ROOT / "benchmarks").glob("*.py"))
#: script -> its arguments that point it at a finished run of config/test.yaml (`{run}`: the
#: run's directory); a script that reads one and is missing here fails on the missing files
RUN_ARGS = {
    "bench_cv_repeats.py": ["--results", "{run}/results"],
    "bench_generator_length.py": ["--results", "{run}/results"],
    "bench_vision.py": ["--results", "{run}/results"],
    "bench_visibility_gate.py": ["--results", "{run}/results"],
}
ALONE = [s for s in SCRIPTS if s not in RUN_ARGS]
#: the scripts that take longest, longest first: started first, so that neither worker is left
#: running one alone at the end
LONG_FIRST = (
    "bench_preload.py",
    "bench_vision.py",
    "bench_visibility_gate.py",
    "bench_estimate.py",
    "bench_pixel.py",
    "machine.py",
    "bench_features.py",
    "bench_sim.py",
)
#: seconds one script may take in its tiny mode on a loaded machine
TIMEOUT_S = 300

#: a figure as Python, numpy and pandas print one
FIGURE = re.compile(r"(?<![\w.])[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:e[-+]?\d+)?", re.I)
NOT_FINITE = re.compile(r"(?<![\w.])[-+]?(?:nan|inf(?:inity)?)(?!\w)", re.I)
TINY_LINE = f"tiny mode ({TINY_ENV})"


def run_script(script: str, args: list[str]) -> subprocess.CompletedProcess:
    """`script` in a fresh interpreter from the repository root, in its tiny mode, with this
    checkout's tacgen_lib first on the path and one BLAS and OpenMP thread (two run at once)."""
    path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    env = {
        **os.environ,
        TINY_ENV: "1",
        "PYTHONPATH": path,
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }
    cmd = [sys.executable, str(ROOT / "benchmarks" / script), *args]
    try:
        return subprocess.run(
            cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=TIMEOUT_S
        )
    except subprocess.TimeoutExpired as err:  # its output comes as bytes, whatever `text` says
        out = err.stdout.decode(errors="replace") if err.stdout else ""
        return subprocess.CompletedProcess(cmd, -1, out, f"timed out after {TIMEOUT_S} s")


def selected(request: pytest.FixtureRequest) -> list[str]:
    """The scripts this session runs (all, unless -k or node ids pick some), longest first."""
    scripts = {
        item.callspec.params["script"]
        for item in request.session.items
        if getattr(item, "originalname", None) in TESTS and hasattr(item, "callspec")
    }
    return sorted(scripts, key=lambda s: (LONG_FIRST + (s,)).index(s))


@pytest.fixture(scope="module")
def launched(request: pytest.FixtureRequest) -> Iterator[dict[str, Future]]:
    """Every selected script, all started at the first test that asks, two at a time (the
    machine's two cores); the run readers on the shared run of config/test.yaml, which is
    built (or waited for) first if any is selected."""
    scripts = selected(request)
    run = request.getfixturevalue("reference_run") if set(scripts) & set(RUN_ARGS) else None
    with ThreadPoolExecutor(max_workers=2) as pool:
        yield {
            s: pool.submit(run_script, s, [a.format(run=run) for a in RUN_ARGS.get(s, ())])
            for s in scripts
        }


def check_output(script: str, proc: subprocess.CompletedProcess) -> None:
    """The script exited 0, said it ran tiny, and printed figures, all finite."""
    tail = f"{script} (exit {proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-6000:]}"
    assert proc.returncode == 0, tail
    assert TINY_LINE in proc.stdout, f"{script} did not run in its tiny mode\n{tail}"
    bad = [line for line in proc.stdout.splitlines() if NOT_FINITE.search(line)]
    assert not bad, f"{script}: figures that are not finite:\n" + "\n".join(bad)
    body = proc.stdout.replace(TINY_LINE, "")
    assert FIGURE.search(body), f"{script} printed no figure\n{tail}"


@pytest.mark.parametrize("script", ALONE)
def test_benchmark_runs_tiny(script: str, launched: dict[str, Future]) -> None:
    check_output(script, launched[script].result())


@pytest.mark.parametrize("script", sorted(RUN_ARGS))
def test_benchmark_runs_tiny_on_a_finished_run(
    script: str, reference_run: Path, launched: dict[str, Future]
) -> None:
    check_output(script, launched[script].result())


#: the tests that run scripts (`selected` starts the scripts of their cases)
TESTS = (test_benchmark_runs_tiny.__name__, test_benchmark_runs_tiny_on_a_finished_run.__name__)


def test_every_run_reader_is_a_script():
    assert set(RUN_ARGS) <= set(SCRIPTS), sorted(set(RUN_ARGS) - set(SCRIPTS))


@pytest.mark.parametrize(
    "line, finite",
    [
        ("ratio 0.75, 12 jobs, -3.2e-05", True),
        ("information: inference 2 frames/s", True),
        ("Delta R2 = nan  CI [nan, nan]", False),
        ("  run V   768   NaN   0.25", False),
        ("speed-up inf", False),
        ("-inf s", False),
    ],
)
def test_the_check_reads_figures_as_printed(line: str, finite: bool) -> None:
    assert (NOT_FINITE.search(line) is None) == finite
    assert FIGURE.search(line) or not finite
