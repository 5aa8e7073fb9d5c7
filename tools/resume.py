"""Continue an interrupted run with one command (`make resume`).

A run killed hard (kill -9, a lost SSH session, an OOM kill) leaves Snakemake's lock in
`.snakemake/locks` and incomplete markers for the jobs that were running; the next plain run
stops with LockException or IncompleteFilesException. This tool:

1. refuses, naming the pid, while a Snakemake of this directory is still alive: its scheduler
   (`snakemake ...` or `python -m snakemake ...` whose working directory, or `--directory`, is
   this one) or a job script it started (`.snakemake/scripts/...` of this directory; a job
   orphaned by a killed scheduler keeps writing its outputs, so it counts as alive too);
2. removes the temporary files the dead run's atomic writers left under `results/` (a
   temporary file is never an edge: edges appear only by rename, `tacgen_lib.io.edges`);
3. clears the dead run's lock as `snakemake --unlock` does (it removes `.snakemake/locks` of
   the run's directory; a second Snakemake process only to do that costs a Snakefile parse),
   then runs `snakemake --rerun-incomplete ARGS`.

"This directory" is the workflow directory: the working directory, or the one a
`--directory` among the arguments names, as Snakemake reads it.

Usage (the Makefile passes --cores):  python tools/resume.py --cores 2 [snakemake args ...]
Standard library only.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

__all__ = ["live_runs", "stale_temporaries", "main"]


def _cmdline(pid: int) -> list[str]:
    with open(f"/proc/{pid}/cmdline", "rb") as fh:
        return [a.decode(errors="replace") for a in fh.read().split(b"\0") if a]


def _ancestors() -> set[int]:
    """This process and its ancestors (make, the shell): never counted as a live run."""
    pids, pid = set(), os.getpid()
    while pid > 1 and pid not in pids:
        pids.add(pid)
        try:
            with open(f"/proc/{pid}/stat") as fh:
                pid = int(fh.read().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            break
    return pids


def _is_scheduler(argv: list[str]) -> bool:
    """`snakemake ...`, `python .venv/bin/snakemake ...` or `python -m snakemake ...`."""
    if any(Path(a).name == "snakemake" for a in argv[:2]):
        return True
    return any(a == "snakemake" and argv[i - 1] == "-m" for i, a in enumerate(argv) if i > 0)


def _run_directory(argv: list[str], cwd: Path) -> Path:
    """The directory a Snakemake command line works in: --directory/-d, else its cwd."""
    for i, arg in enumerate(argv):
        if arg in ("--directory", "-d") and i + 1 < len(argv):
            return (cwd / argv[i + 1]).resolve()
        if arg.startswith("--directory="):
            return (cwd / arg.split("=", 1)[1]).resolve()
    return cwd


def live_runs(workdir: str | os.PathLike) -> list[tuple[int, str]]:
    """(pid, command line) of every live Snakemake scheduler or job script of `workdir`."""
    workdir = Path(workdir).resolve()
    scripts = str(workdir / ".snakemake" / "scripts") + os.sep
    skip = _ancestors()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) in skip:
            continue
        pid = int(entry.name)
        try:
            argv = _cmdline(pid)
            cwd = Path(os.readlink(entry / "cwd")).resolve()
        except OSError:  # exited meanwhile, or not ours to inspect
            continue
        if not argv:  # a zombie: already dead
            continue
        job = any(a.startswith(scripts) for a in argv) or (
            cwd == workdir and any(".snakemake/scripts/" in a for a in argv)
        )
        if job or (_is_scheduler(argv) and _run_directory(argv, cwd) == workdir):
            found.append((pid, " ".join(argv)))
    return sorted(found)


def stale_temporaries(workdir: str | os.PathLike) -> list[Path]:
    """Temporary files left under results/ by atomic writers of a dead run
    (`.<name>.<random>.tmp` from tacgen_lib.io.edges, `<name>.tmp` from checkpoint savers)."""
    results = Path(workdir) / "results"
    if not results.is_dir():
        return []
    return sorted(p for p in results.rglob("*.tmp") if p.is_file())


def main(args: list[str]) -> int:
    workdir = Path.cwd()
    rundir = _run_directory(args, workdir)  # the workflow directory (--directory, else here)
    live = live_runs(rundir)
    if live:
        lines = "\n".join(f"  pid {pid}: {cmd[:200]}" for pid, cmd in live)
        print(
            f"resume: refused: a Snakemake run is still alive in {rundir}:\n{lines}\n"
            "Wait for it to finish, or stop it (kill <pid>) and run `make resume` again. "
            "Its lock is not stale, so it is left alone.",
            file=sys.stderr,
        )
        return 3
    leftovers = stale_temporaries(rundir)
    for path in leftovers:
        path.unlink(missing_ok=True)
    if leftovers:
        print(f"resume: removed {len(leftovers)} temporary file(s) of the dead run", flush=True)
    # what `snakemake --unlock` does (snakemake.persistence: the locks folder is removed); no
    # Snakemake of the directory is alive (above), so every lock in it is stale
    shutil.rmtree(rundir / ".snakemake" / "locks", ignore_errors=True)
    snakemake = [sys.executable, "-m", "snakemake"]
    print("resume: lock cleared; rerunning incomplete jobs and everything not yet made", flush=True)
    return subprocess.run([*snakemake, "--rerun-incomplete", *args], cwd=workdir).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
