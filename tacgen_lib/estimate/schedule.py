"""List scheduling of a DAG's jobs on cores: the wall time of a run, given each job's seconds.

What `snakemake --cores N` does: a job starts once every job it waits for has finished and
enough cores are free for its `threads` (capped at the cores of one machine, as Snakemake caps
them); among ready jobs the one with the longest remaining chain goes first, and smaller jobs
fill cores a bigger one cannot use. A plain sum / N is wrong when the DAG has a long serial
chain: the chain's length is a floor no core count removes.

On a SLURM cluster each job is an sbatch job on one node of K: it needs its threads free on a
single node and waits `queue_s` (queueing and start-up on the node) before it runs; at most
`max_jobs` are queued or running (the profile's `jobs:`). `localrules` jobs run on the
submitting host instead, on its `local_cores`, without queueing.
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "Task",
    "Machine",
    "Schedule",
    "critical_chain",
    "list_schedule",
    "local_machine",
    "longest_first_makespan",
    "slurm_machine",
]


@dataclass(frozen=True)
class Task:
    """One job to place: `key` (unique), `seconds` it runs, `threads` it needs, `deps` (keys of
    the tasks it waits for), `local` (a localrules job: on the host, not the cluster)."""

    key: int
    seconds: float
    threads: int = 1
    deps: tuple[int, ...] = ()
    local: bool = False


@dataclass(frozen=True)
class Machine:
    """Where tasks run: `nodes` (cores of each compute node), `queue_s` per non-local job,
    `max_jobs` non-local jobs at once (None: no limit), `local_cores` of the submitting host
    (None: local jobs run on the nodes like any other, as on one workstation)."""

    nodes: tuple[int, ...]
    queue_s: float = 0.0
    max_jobs: int | None = None
    local_cores: int | None = None

    def __post_init__(self) -> None:
        if not self.nodes or min(self.nodes) < 1:
            raise ValueError(f"a machine needs at least one node of >= 1 core, got {self.nodes}")
        if self.queue_s < 0:
            raise ValueError(f"queue_s must be >= 0, got {self.queue_s}")


def local_machine(cores: int) -> Machine:
    """One workstation with `cores` cores (`snakemake --cores N`)."""
    return Machine(nodes=(int(cores),))


def slurm_machine(
    nodes: int,
    cores_per_node: int,
    *,
    queue_s: float = 30.0,
    max_jobs: int | None = 50,
    local_cores: int = 2,
) -> Machine:
    """K SLURM nodes of C cores each, a per-job queue/start overhead, the profile's job limit
    (profiles/slurm: `jobs: 50`) and the submitting host's cores for `localrules` jobs."""
    return Machine(
        nodes=(int(cores_per_node),) * int(nodes),
        queue_s=float(queue_s),
        max_jobs=max_jobs,
        local_cores=int(local_cores),
    )


@dataclass(frozen=True)
class Schedule:
    """Start and end second of every task (by key), and the makespan (the run's wall time)."""

    start: dict[int, float]
    end: dict[int, float]

    @property
    def makespan(self) -> float:
        return max(self.end.values(), default=0.0)


def _remaining_chain(tasks: Sequence[Task], by_key: dict[int, Task]) -> dict[int, float]:
    """Longest path (seconds) from each task's start to the end of the DAG (its priority)."""
    order = _topological(tasks, by_key)
    children: dict[int, list[int]] = {t.key: [] for t in tasks}
    for t in tasks:
        for d in t.deps:
            children[d].append(t.key)
    rank: dict[int, float] = {}
    for key in reversed(order):
        rank[key] = by_key[key].seconds + max((rank[c] for c in children[key]), default=0.0)
    return rank


def _topological(tasks: Sequence[Task], by_key: dict[int, Task]) -> list[int]:
    indeg = {t.key: len(t.deps) for t in tasks}
    children: dict[int, list[int]] = {t.key: [] for t in tasks}
    for t in tasks:
        for d in t.deps:
            if d not in by_key:
                raise ValueError(f"task {t.key} waits for unknown task {d}")
            children[d].append(t.key)
    ready = sorted(k for k, n in indeg.items() if n == 0)
    order = []
    while ready:
        k = ready.pop()
        order.append(k)
        for c in children[k]:
            indeg[c] -= 1
            if indeg[c] == 0:
                ready.append(c)
    if len(order) != len(tasks):
        raise ValueError("the tasks' dependencies form a cycle")
    return order


def list_schedule(tasks: Sequence[Task], machine: Machine) -> Schedule:
    """Place every task as early as its dependencies and free cores allow (list scheduling,
    longest remaining chain first, smaller tasks back-filling cores a larger one cannot use).

    A task needs min(threads, cores of its node) cores on one node; non-local tasks on a
    machine with `queue_s` hold their cores for `queue_s + seconds` (the queue wait is modelled
    as time on the node, a pessimistic simplification when the cluster is idle).
    """
    by_key = {t.key: t for t in tasks}
    if len(by_key) != len(tasks):
        raise ValueError("task keys must be unique")
    rank = _remaining_chain(tasks, by_key)
    host = (machine.local_cores,) if machine.local_cores else ()
    cap = {("node", i): c for i, c in enumerate(machine.nodes)}
    cap.update({("host", i): c for i, c in enumerate(host)})
    free = dict(cap)
    waiting = {t.key: len(t.deps) for t in tasks}
    children: dict[int, list[int]] = {t.key: [] for t in tasks}
    for t in tasks:
        for d in t.deps:
            children[d].append(t.key)
    ready = [(-rank[k], k) for k, n in waiting.items() if n == 0]
    heapq.heapify(ready)
    running: list[tuple[float, int, tuple[str, int], int]] = []  # (end, key, slot, cores)
    start: dict[int, float] = {}
    end: dict[int, float] = {}
    remote_running = 0
    now = 0.0
    while ready or running:
        # 1. start every ready task that fits, in priority order (skipped ones wait)
        skipped = []
        while ready:
            prio, key = heapq.heappop(ready)
            task = by_key[key]
            on_host = bool(host) and task.local
            if not on_host and machine.max_jobs is not None and remote_running >= machine.max_jobs:
                skipped.append((prio, key))
                continue
            fit = _fit(free, cap, "host" if on_host else "node", max(1, task.threads))
            if fit is None:
                skipped.append((prio, key))
                continue
            slot, cores = fit
            free[slot] -= cores
            wait = 0.0 if on_host else machine.queue_s
            start[key] = now
            end[key] = now + wait + task.seconds
            remote_running += not on_host
            heapq.heappush(running, (end[key], key, slot, cores))
        for item in skipped:
            heapq.heappush(ready, item)
        if not running:
            if ready:
                raise ValueError(f"task {ready[0][1]} can never start (no node fits it)")
            break
        # 2. advance to the next finish; release its cores and wake its children
        now, key, slot, cores = heapq.heappop(running)
        finished = [(key, slot, cores)]
        while running and running[0][0] <= now:
            _, k2, s2, c2 = heapq.heappop(running)
            finished.append((k2, s2, c2))
        for k, s, c in finished:
            free[s] += c
            remote_running -= s[0] == "node"
            for child in children[k]:
                waiting[child] -= 1
                if waiting[child] == 0:
                    heapq.heappush(ready, (-rank[child], child))
    return Schedule(start, end)


def _fit(
    free: dict[tuple[str, int], int], cap: dict[tuple[str, int], int], kind: str, threads: int
) -> tuple[tuple[str, int], int] | None:
    """First slot of `kind` with room for the task, and the cores it takes there: its threads,
    capped at the slot's size (Snakemake caps a job's threads at the cores it has)."""
    for s in free:
        if s[0] == kind:
            need = min(threads, cap[s])
            if free[s] >= need:
                return s, need
    return None


def longest_first_makespan(seconds: Sequence[float], workers: int) -> float:
    """Wall time of independent items of `seconds` on `workers` one-thread workers, handed out
    longest first (`tacgen_lib.runtime.workers.fork_map` with a cost): each goes to the worker
    that frees first. Never below the longest item, nor below the sum / workers."""
    free = [0.0] * max(1, min(int(workers), len(seconds) or 1))
    heapq.heapify(free)
    for s in sorted(seconds, reverse=True):
        heapq.heappush(free, heapq.heappop(free) + float(s))
    return max(free)


def critical_chain(tasks: Sequence[Task]) -> tuple[float, list[int]]:
    """The DAG's longest chain of dependent tasks by seconds (the wall time no number of cores
    removes) and its task keys, first to last."""
    by_key = {t.key: t for t in tasks}
    rank = _remaining_chain(tasks, by_key)
    children: dict[int, list[int]] = {t.key: [] for t in tasks}
    for t in tasks:
        for d in t.deps:
            children[d].append(t.key)
    roots = [t.key for t in tasks if not t.deps]
    if not roots:
        return 0.0, []
    key = max(roots, key=lambda k: rank[k])
    chain = [key]
    while children[key]:
        key = max(children[key], key=lambda k: rank[k])
        chain.append(key)
    return rank[chain[0]], chain
