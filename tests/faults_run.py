"""Killing and resuming workflow runs from tests: shared by the fault tests and the
session's kill series (conftest.resumed_run), which also serves as the independent second
computation of every edge that the determinism test compares with the reference run.

A plain module (pytest puts tests/ on sys.path), like snakemake_run.py.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from snakemake_run import ROOT, SNAKEMAKE, smk

from tacgen_lib.io import hashed

sys.path.insert(0, str(ROOT / "tools"))
import resume  # noqa: E402 - tools/ is not a package

#: stage -> the rule whose running job the whole-run kill interrupts, in DAG order. One row per
#: stage; a new stage is one more row.
KILL_STAGES: dict[str, str] = {
    "corpus": "simulate_corpus",
    "preprocess": "background_subtract",
    "features": "pretrain_backbone",
    "backbones": "family_backbone",
    "align": "train_heads",
    "generate": "train_generator",
    "probes": "probe",
    "policy": "train_policy",
    "report": "edge_manifest",
}

RESUME = [sys.executable, str(ROOT / "tools/resume.py"), "--cores", "2"]
CONFIG = ["--configfile", "config/test.yaml"]
START_TIMEOUT = 600  # seconds to wait for a job of a stage to start


def _scripts_of_rules() -> dict[str, str]:
    """rule -> the stem of its script (`script: "../workflow/scripts/<stem>.py"`)."""
    out: dict[str, str] = {}
    text = "\n".join(p.read_text() for p in sorted((ROOT / "rules").glob("*.smk")))
    for block in re.split(r"(?m)^(?=rule \w+:)", text):
        name = re.match(r"rule (\w+):", block)
        script = re.search(r'script:\s*"\.\./workflow/scripts/(\w+)\.py"', block)
        if name and script:
            out[name.group(1)] = script.group(1)
    return out


SCRIPTS = _scripts_of_rules()


def running_jobs(work: Path, rules: list[str]) -> dict[str, list[int]]:
    """rule -> pids of its live job processes in `work`, for those of `rules` with one
    (Snakemake runs a script as `python <work>/.snakemake/scripts/tmpXXXX.<script>.py`; the
    processes are listed once for all the rules)."""
    live = [(pid, cmd) for pid, cmd in resume.live_runs(work) if ".snakemake/scripts/" in cmd]
    out: dict[str, list[int]] = {}
    for rule in rules:
        tail = f".{SCRIPTS[rule]}.py"
        pids = [pid for pid, cmd in live if tail in cmd]
        if pids:
            out[rule] = pids
    return out


def _scheduled(work: Path, rules: list[str]) -> list[str]:
    """Those of `rules` of which Snakemake's own log of the newest run says a job was started."""
    logs = sorted((work / ".snakemake/log").glob("*.snakemake.log"))
    text = logs[-1].read_text() if logs else ""
    return [r for r in rules if re.search(rf"(?m)^(local)?rule {r}:", text) is not None]


def _recorded(work: Path) -> bool:
    """Snakemake has recorded a started job: its incomplete marker is written. Snakemake's
    local executor starts the job's process before it writes the marker, so a job seen running
    may not be recorded yet; killed in that moment, the run would leave no marker behind."""
    marks = work / ".snakemake/incomplete"
    return marks.is_dir() and any(p.is_file() for p in marks.rglob("*"))


def wait_for_job(proc: subprocess.Popen, work: Path, rule: str) -> list[int] | None:
    """Pids of a running job of `rule`, or None if the run ended first."""
    found = wait_for_any_job(proc, work, [rule])
    return None if found is None else found[1]


def wait_for_any_job(
    proc: subprocess.Popen, work: Path, rules: list[str]
) -> tuple[str, list[int]] | None:
    """The first of `rules` seen with a running job that Snakemake has recorded as started
    (`_recorded`; in the order of `rules` when several are), and its pids; None if the run
    ended first."""
    deadline = time.monotonic() + START_TIMEOUT
    while time.monotonic() < deadline:
        # the processes are listed only once the log names a job of one of the rules (most
        # polls read the log alone)
        scheduled = _scheduled(work, rules)
        running = running_jobs(work, scheduled) if scheduled else {}
        for rule in scheduled:
            if rule in running and _recorded(work):
                return rule, running[rule]
        if proc.poll() is not None:
            return None
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGKILL)
    raise AssertionError(f"no job of the rules {rules} started within {START_TIMEOUT} s")


def wait_dead(work: Path, timeout: float = 30) -> None:
    deadline = time.monotonic() + timeout
    while resume.live_runs(work):
        assert time.monotonic() < deadline, resume.live_runs(work)
        time.sleep(0.1)


def launch(work: Path, cmd: list[str], log: Path) -> subprocess.Popen:
    """Start `cmd` in `work` in its own process group (so the whole run can be killed)."""
    return subprocess.Popen(
        cmd, cwd=work, stdout=log.open("ab"), stderr=subprocess.STDOUT, start_new_session=True
    )


def assert_no_half_written_edge(work: Path) -> int:
    """Every edge present beside its sidecar verifies (the atomic writers only ever rename a
    complete file into place). Returns how many were checked."""
    checked = 0
    for side in (work / "results").rglob("*" + hashed.SIDECAR_SUFFIX):
        edge = side.with_name(side.name.removesuffix(hashed.SIDECAR_SUFFIX))
        if edge.exists():
            hashed.verify(edge)
            checked += 1
    return checked


def kill_series(work: Path) -> dict:
    """A cold run of config/test.yaml in `work`, SIGKILLed (its whole process group) while a
    job of each stage in `KILL_STAGES` runs, each time restarted by the one recovery command
    (`tools/resume.py`, what `make resume` runs); a last resume runs it to the end.

    Each run is killed at the first job of a stage not yet killed that the scheduler starts,
    so the stages are killed in the order the scheduler reaches them, not `KILL_STAGES`'s:
    waiting for one stage's rule would let the run finish the stages the scheduler runs
    before it (the priorities of tacgen_lib/plan/priorities.py start the alignment heads and the generators
    before the backbone families, the policy before the probes), and each of them would then
    be forced again, with everything downstream of it (measured: 128 s against 99 s for the
    whole series). Only a run that ends before any stage left is reached is followed by one
    forced (`--forcerun`) run of every stage left.

    Returns what a user finds after each kill (`kills[stage]`: the job's pids, whether a
    stale lock and an incomplete marker are left, how many edges verify or the error of the
    one that did not, and, after the first kill, a plain rerun's output and exit code) and
    after the last resume (`final`): observations, not assertions, so that each stage's test
    reports its own failure."""
    log = work / "run.log"
    kills: dict[str, dict] = {}
    stage_of = {rule: stage for stage, rule in KILL_STAGES.items()}
    started = False
    while len(kills) < len(KILL_STAGES):
        left = [rule for stage, rule in KILL_STAGES.items() if stage not in kills]
        # cold the first time; afterwards the one recovery command after the previous kill
        cmd = RESUME + CONFIG if started else [*SNAKEMAKE, "--cores", "2", *CONFIG]
        t0 = time.monotonic()
        proc = launch(work, cmd, log)
        started = True
        found = wait_for_any_job(proc, work, left)
        forced_exit = None
        if found is None:  # the run finished before any stage left: force them all again
            forced_exit = proc.returncode
            force = [*SNAKEMAKE, "--cores", "2", *CONFIG, "--forcerun", *left]
            proc = launch(work, force, log)
            found = wait_for_any_job(proc, work, left)
            if found is None:
                raise AssertionError(f"no job of {left} to kill:\n{log.read_text()[-4000:]}")
        rule, pids = found
        stage = stage_of[rule]
        os.killpg(proc.pid, signal.SIGKILL)  # the whole run: scheduler, resume wrapper and jobs
        proc.wait()
        wait_dead(work)
        seen = {
            "rule": rule,
            "pids": pids,
            "finished_early_exit": forced_exit,
            "seconds": round(time.monotonic() - t0, 1),
            "lock": bool(list((work / ".snakemake/locks").iterdir())),
            "incomplete": bool(list((work / ".snakemake/incomplete").iterdir())),
            "log_tail": log.read_text()[-4000:],
        }
        try:
            seen["edges_verified"], seen["edge_error"] = assert_no_half_written_edge(work), None
        except Exception as err:  # noqa: BLE001 - reported by the stage's test
            seen["edges_verified"], seen["edge_error"] = 0, repr(err)
        if not kills:  # once: a plain rerun is refused
            seen["plain_rerun"] = smk(work, check=False)
        kills[stage] = seen
    t0 = time.monotonic()
    proc = launch(work, RESUME + CONFIG, log)
    exit_code = proc.wait(timeout=900)
    final = {
        "exit": exit_code,
        "seconds": round(time.monotonic() - t0, 1),
        "log": log.read_text(),
    }
    return {"work": work, "kills": kills, "final": final}
