"""The alignment fan-out through a REAL single-node SLURM cluster and profiles/slurm.

Opt-in for pytest, because it installs Debian packages and starts daemons as root; `make test`
(and so CI) opts in. Most of its time is the session's local run it starts from:

    TACGEN_SLURM_TEST=1 python -m pytest tests/test_slurm.py -v -s

What it does, as root on Debian/Ubuntu: `apt-get install slurm-wlm munge` (a no-op when they
are installed), writes a one-node /etc/slurm/slurm.conf (the executor plugin's job step drops
SLURM_CONF, so the config must be at the default path; an existing file is backed up and put
back), starts munged, slurmctld and slurmd in the foreground as children of this test, takes
the tiny workflow's upstream (corpus, features) from a copy of the session's local run of
config/test.yaml (conftest.reference_run) with its align and generate outputs removed, then
runs the alignment grid of config/test.yaml (one seed and tau on its two corpora) and one
generator through `--profile profiles/slurm` (every train_heads and train_generator job an
sbatch job; aggregate_align local), at the local run's thread counts, so that every edge the
cluster makes must equal the local run's bit for bit. Without slurmdbd there is no accounting
database, so the profile queries job status with squeue. Everything it started is stopped at
the end (jobs cancelled, then slurmd, slurmctld, munged by their pids), also on failure or
timeout. It skips, printing why, when it cannot run: not root, no apt-get, a SLURM already
running here, install failure, or daemons that do not come up.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from snakemake_run import SNAKEMAKE, copy_run, edge_hashes, planned_rules

pytestmark = [pytest.mark.slurm, pytest.mark.workflow]

RUN_TIMEOUT = 600  # seconds for the SLURM run itself; the test fails (and cleans up) after it
SLURM_CONF = Path("/etc/slurm/slurm.conf")
#: the grid fanned out: test.yaml's own (one seed and tau on its 2 corpora; every sbatch job
#: starts an interpreter and imports torch, so more cells would cost more and assert nothing
#: new), so the session's local run holds every edge the cluster makes
GRID = {"seeds": [42], "taus": [0.07]}
#: the local run's threads for the jobs the cluster runs (the profile gives them 2): edges are
#: bit-identical per thread count, so at these the cluster's must equal the local run's
LOCAL_THREADS = ["--set-threads", "train_heads=1", "train_generator=1"]
#: generate: one generator trained through SLURM beside the alignment grid.
GENERATOR_WEIGHTS = "results/generate/sim_paired/seed~0/generator.arrow"


def _skip(reason: str) -> None:
    print(f"\nSKIP test_slurm: {reason}", flush=True)
    pytest.skip(reason)


def _run(cmd: list[str], timeout: float, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, **kw)


def _install() -> None:
    if shutil.which("slurmctld") and shutil.which("munged"):
        return
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (["apt-get", "update"], ["apt-get", "install", "-y", "slurm-wlm", "munge"]):
        try:
            proc = _run(cmd, timeout=300, env=env)
        except subprocess.TimeoutExpired:
            _skip(f"{' '.join(cmd)} took more than 300 s")
        if proc.returncode != 0:
            _skip(f"{' '.join(cmd)} failed: {proc.stderr[-800:]}")


def _slurm_conf(state: Path) -> str:
    host = socket.gethostname().split(".")[0]
    cpus = os.cpu_count() or 1
    with open("/proc/meminfo") as fh:
        mem_kb = int(next(line for line in fh if line.startswith("MemTotal")).split()[1])
    real_mb = max(1000, int(mem_kb / 1024 * 0.8))
    return f"""# Written by tests/test_slurm.py for a one-node test cluster; removed afterwards.
ClusterName=tacgentest
SlurmctldHost={host}(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation={state}/ctld
SlurmdSpoolDir={state}/d
SlurmctldPidFile={state}/slurmctld.pid
SlurmdPidFile={state}/slurmd.pid
SlurmctldLogFile={state}/slurmctld.log
SlurmdLogFile={state}/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
MailProg=/bin/true
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU_Memory
DefMemPerCPU=1000
MinJobAge=600
ReturnToService=2
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={real_mb} State=UNKNOWN
PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""


def _stop(proc: subprocess.Popen, name: str) -> None:
    """Stop one daemon this test started (by its pid), TERM then KILL."""
    if proc.poll() is not None:
        return
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        print(f"{name} (pid {proc.pid}) ignored SIGTERM; killing it", flush=True)
        proc.kill()
        proc.wait(timeout=10)


def _wait_idle(timeout: float = 30) -> str:
    deadline, state = time.monotonic() + timeout, ""
    while time.monotonic() < deadline:
        with contextlib.suppress(subprocess.TimeoutExpired):
            state = _run(["sinfo", "-h", "-o", "%T"], timeout=10).stdout.strip()
            if state.startswith("idle"):
                return state
        time.sleep(0.5)
    return state


@contextlib.contextmanager
def single_node_slurm(state: Path) -> Iterator[Path]:
    """munged + slurmctld + slurmd on localhost for the duration of the block."""
    if os.geteuid() != 0:
        _skip("needs root (installs slurm-wlm and munge, starts daemons)")
    if not shutil.which("apt-get") and not shutil.which("slurmctld"):
        _skip("no apt-get to install slurm-wlm and munge")
    if shutil.which("pgrep"):
        for daemon in ("slurmctld", "slurmd"):
            if _run(["pgrep", "-x", daemon], timeout=10).returncode == 0:
                _skip(f"a {daemon} is already running on this machine; not touching it")
    started = time.monotonic()
    _install()
    print(f"slurm-wlm + munge present after {time.monotonic() - started:.0f} s", flush=True)

    for sub in ("ctld", "d"):
        (state / sub).mkdir(parents=True, exist_ok=True)
    backup = None
    if SLURM_CONF.exists():
        backup = SLURM_CONF.with_name("slurm.conf.tacgen-test-backup")
        shutil.copy2(SLURM_CONF, backup)
    SLURM_CONF.parent.mkdir(parents=True, exist_ok=True)
    SLURM_CONF.write_text(_slurm_conf(state))
    daemons: list[tuple[str, subprocess.Popen]] = []
    try:
        munge_run = Path("/run/munge")
        munge_key = Path("/etc/munge/munge.key")
        if _run(["pgrep", "-x", "munged"], timeout=10).returncode != 0:
            munge_run.mkdir(parents=True, exist_ok=True)
            shutil.chown(munge_run, "munge", "munge")
            if not munge_key.exists():
                _run(["runuser", "-u", "munge", "--", "mungekey", "--create"], timeout=30)
            munged = subprocess.Popen(
                ["runuser", "-u", "munge", "--", "/usr/sbin/munged", "--foreground"],
                stdout=subprocess.DEVNULL,
                stderr=open(state / "munged.log", "w"),  # noqa: SIM115 - closed with the process
            )
            daemons.append(("munged", munged))
            for _ in range(50):
                if (munge_run / "munge.socket.2").exists():
                    break
                time.sleep(0.1)
        for name, cmd in (("slurmctld", ["slurmctld", "-D", "-i"]), ("slurmd", ["slurmd", "-D"])):
            daemons.append(
                (
                    name,
                    subprocess.Popen(
                        cmd, stdout=subprocess.DEVNULL, stderr=open(state / f"{name}.err", "w")
                    ),
                )
            )
            time.sleep(0.5)
        node = _wait_idle()
        dead = [n for n, p in daemons if p.poll() is not None]
        if dead or not node.startswith("idle"):
            logs = "".join(
                f"\n--- {f.name}\n{f.read_text()[-1500:]}"
                for f in sorted(state.glob("*.log")) + sorted(state.glob("*.err"))
            )
            _skip(f"SLURM did not come up (exited: {dead}, node state {node!r}){logs}")
        print(f"single-node SLURM up after {time.monotonic() - started:.0f} s", flush=True)
        yield state
    finally:
        if any(n == "slurmctld" and p.poll() is None for n, p in daemons):
            # every job on this private cluster was submitted by this test
            with contextlib.suppress(Exception):
                _run(["scancel", "--full", "--user", "root"], timeout=30)
                for _ in range(60):
                    if not _run(["squeue", "-h", "-t", "R,CG,PD"], timeout=10).stdout.strip():
                        break
                    time.sleep(0.5)
        for name, proc in reversed(daemons):
            _stop(proc, name)
        if backup is not None:
            shutil.move(backup, SLURM_CONF)
        else:
            SLURM_CONF.unlink(missing_ok=True)


# a dying cluster job
def _cancel_one_running(proc: subprocess.Popen, rule: str, timeout: float = 300) -> str | None:
    """scancel the first job of `rule` seen RUNNING (a node failure, a preemption, an admin's
    scancel); returns its job id, or None if the run ended before one ran."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        with contextlib.suppress(subprocess.TimeoutExpired):
            running = _run(["squeue", "-h", "-t", "R", "-o", "%i|%k"], timeout=10).stdout
            for line in running.splitlines():
                job_id, _, comment = line.partition("|")
                if rule in comment:
                    time.sleep(1.0)  # let it get going
                    _run(["scancel", job_id.strip()], timeout=30)
                    print(f"scancel {job_id.strip()} ({rule}) mid-run", flush=True)
                    return job_id.strip()
        time.sleep(0.5)
    return None


@pytest.mark.skipif(
    os.environ.get("TACGEN_SLURM_TEST") != "1",
    reason="set TACGEN_SLURM_TEST=1 to run the alignment grid through a real one-node SLURM "
    "(installs slurm-wlm + munge as root, ~2-3 min); make test sets it",
)
def test_align_grid_through_slurm_profile(reference_run, tmp_path):
    from tacgen_lib.io import hashed

    # the upstream (corpus, splits, features) is the session's local run of config/test.yaml
    # (conftest.reference_run); the stages the SLURM run makes start empty, so every grid cell
    # and the generator are made here
    work = copy_run(reference_run, tmp_path / "wf")
    shutil.rmtree(work / "results/align")
    shutil.rmtree(work / "results/generate")
    cfg = yaml.safe_load((work / "config/test.yaml").read_text())
    assert {k: cfg["align"][k] for k in GRID} == GRID, cfg["align"]
    corpora = ["sim_paired", "sim_null"]
    n_cells = len(corpora) * len(GRID["seeds"]) * len(GRID["taus"])
    targets = [
        "results/align/summary.parquet",
        "results/report/align/seeds.html",
        GENERATOR_WEIGHTS,
    ]
    # (targets after an option: a bare word following --configfile would be read as a config)
    planned = planned_rules(work, "--cores", "2", *targets, "--configfile", "config/test.yaml")
    # nothing upstream reruns: only the grid, its aggregate and the generator are left to make
    assert planned == {"train_heads": n_cells, "aggregate_align": 1, "train_generator": 1}, planned

    with single_node_slurm(tmp_path / "slurm") as state:
        cmd = [
            *SNAKEMAKE,
            *targets,  # generate: one train_generator job through SLURM
            "--profile",
            "profiles/slurm",
            *LOCAL_THREADS,
            "--configfile",
            "config/test.yaml",
            "--slurm-init-seconds-before-status-checks",
            "1",
            "--slurm-no-account",
            "--slurm-keep-successful-logs",
        ]
        t0 = time.monotonic()
        # a dying cluster job
        # scancel one running train_heads job mid-run: the profile's `retries` resubmit it
        run_log = tmp_path / "slurm_run.log"
        with run_log.open("w") as out:
            proc = subprocess.Popen(cmd, cwd=work, stdout=out, stderr=subprocess.STDOUT)
            cancelled = _cancel_one_running(proc, "train_heads")
            try:
                proc.wait(timeout=RUN_TIMEOUT)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
                ctld = (state / "slurmctld.log").read_text()[-3000:]
                pytest.fail(
                    f"the SLURM run did not finish in {RUN_TIMEOUT} s\n"
                    f"{run_log.read_text()[-4000:]}\n--- slurmctld.log\n{ctld}"
                )
        elapsed = time.monotonic() - t0
        print(f"alignment grid through SLURM in {elapsed:.0f} s (cancelled job {cancelled})")
        assert proc.returncode == 0, run_log.read_text()[-6000:]
        assert cancelled is not None, "no train_heads job was seen running to cancel"
        ctld_log = (state / "slurmctld.log").read_text()
        # finished jobs stay visible for MinJobAge: what each sbatch job asked for
        jobs = _run(["squeue", "-h", "-t", "all", "-o", "%k|%C|%m|%T"], timeout=10).stdout

    slurm_logs = list((work / ".snakemake/slurm_logs/rule_train_heads").rglob("*.log"))
    # one sbatch job per grid cell, and one more: the resubmission of the cancelled one
    assert n_cells <= len(slurm_logs) <= n_cells + 1, slurm_logs
    assert not (work / ".snakemake/slurm_logs/rule_aggregate_align").exists()  # localrule
    # every cell ran and exited 0 as a SLURM job (started by the main scheduler or backfill,
    # whose log lines differ: count completions, not one scheduler's wording)
    assert len(set(re.findall(r"_job_complete: JobId=(\d+) WEXITSTATUS 0", ctld_log))) >= n_cells
    heads_jobs = [line.split("|") for line in jobs.splitlines() if "train_heads" in line]
    assert len(heads_jobs) == n_cells + 1, jobs  # the cancelled job and its resubmission
    states = sorted((cpus, mem, status) for _comment, cpus, mem, status in heads_jobs)
    # the profile's set-resources: attempt 1 asks 4000M; the retry of the cancelled cell is
    # attempt 2 and asks twice that ("4000 * attempt")
    assert states.count(("2", "4000M", "CANCELLED")) == 1, jobs
    assert states.count(("2", "8000M", "COMPLETED")) == 1, jobs
    assert states.count(("2", "4000M", "COMPLETED")) == n_cells - 1, jobs
    summary = __import__("pandas").read_parquet(work / "results/align/summary.parquet")
    assert len(summary) == n_cells
    assert sorted(set(summary["tau"])) == [str(t) for t in GRID["taus"]]
    assert sorted(set(summary["seed"])) == GRID["seeds"]
    assert (summary["train_seconds"] > 0).all()
    for cell in summary["cell"]:
        hashed.verify(work / "results/align" / cell / "metrics.parquet")
        hashed.verify(work / "results/align" / cell / "heads.pt")
    assert (work / "results/report/align/seeds.html").stat().st_size > 500
    # every edge the cluster made equals the session's local run's (same code, config and
    # thread counts)
    got, want = edge_hashes(work), edge_hashes(reference_run)
    for cell in summary["cell"]:
        for name in ("heads.pt", "metrics.parquet", "curve.parquet"):
            assert f"results/align/{cell}/{name}.sha256.json" in got, cell
    assert f"{GENERATOR_WEIGHTS}.sha256.json" in got
    assert {k: v for k, v in got.items() if want.get(k) != v} == {}
    # generate: the train_generator job ran as an sbatch job with its resources
    gen_logs = list((work / ".snakemake/slurm_logs/rule_train_generator").rglob("*.log"))
    assert len(gen_logs) == 1, gen_logs
    gen_jobs = [line.split("|") for line in jobs.splitlines() if "train_generator" in line]
    assert [(c, m, st) for _k, c, m, st in gen_jobs] == [("2", "3000M", "COMPLETED")], jobs
    hashed.verify(work / GENERATOR_WEIGHTS)
