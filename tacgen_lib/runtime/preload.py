"""A preloaded interpreter for the workflow's script jobs: a fork server.

Most jobs of a small config are start-up: a fresh interpreter importing torch, scikit-learn,
scipy and pandas spends 1-3 CPU-seconds before its first line of work, longer than many jobs'
work. On a local run (`snakemake --cores N`, never on a cluster executor) the Snakefile's
`onstart` starts one server per Snakemake process
(`tacgen_lib.runtime.preload_server.start_preloaded_interpreter`): it imports
`PRELOADED_MODULES` (third-party only: the workflow's own code is imported fresh by every
job, as it would be without the server) and waits on an abstract Unix socket. Every workflow
script begins with `run_in_preloaded_interpreter(snakemake)`: the job's process (started by
Snakemake's `script:` directive as usual) sends the server its script file, working
directory, environment and standard streams, and the server forks a copy of itself that runs
the script, exactly as the fresh interpreter would have, after the imports.

What a job sees is what a fresh interpreter gives it:
- its own environment, working directory, `sys.argv` and standard streams;
- its thread counts: a fresh interpreter's OpenMP, BLAS and torch pools are sized by the
  `OMP_NUM_THREADS` (and BLAS) variables Snakemake sets for the job, which the server read
  before the job existed, so the copy sizes every pool (`threadpoolctl`, `torch`) from them;
- its exit status, and its signals: the job process forwards SIGTERM, SIGINT and SIGHUP to the
  copy (those it ignores, the copy ignores too, as a fresh interpreter inherits an ignored
  signal), and if the job process dies (even by SIGKILL) the copy is killed.

Snakemake's `benchmark:` measures the job's own process tree, which no longer holds the work:
its wall time `s` is still the job's, but its CPU time and memory are not. The copy's exact
resource usage (`wait4`) is written beside the benchmark file (`usage_path`) and
`tacgen_lib.runtime.benchmarks.read_benchmark` adds it. A job that runs in a fresh interpreter
removes a stale file there first.

The server listens before it imports and forks the jobs waiting for it between two imports:
it imports what a run's first jobs need first (the simulator's modules, ~2 s), so they start
then, and the heavy rest (scikit-learn, torch, matplotlib) before the jobs that need it come;
a job forked earlier imports what is still missing itself, as it would fresh. If no server
answers (a cluster job, a Python run outside Snakemake, a server gone), or the server declines
the job, the job runs in its own interpreter: the server only ever saves start-up time.
`TACGEN_PRELOAD=0` turns it off.

A job runs in the server only where a fresh interpreter would be the server's own
(`preload_server._mismatch`): the same interpreter (its real path), `sys.prefix`, `sys.exec_prefix`,
`sys.base_prefix` and Python version (so a rule with `conda:` under `--sdm conda` runs in its
environment's interpreter, never in the server's `.venv`), the same environment variables read
at import time (every `PYTHON*` and `LD_*` variable, as the server started; the thread counts
differ per job and are applied to the copy instead), and mujoco's OpenGL backend
(`ENVIRONMENT_PRELOADS`). Otherwise the server answers why, the job runs fresh, and
`tacgen_lib.io.log.for_rule` writes the reason into the rule's log (`fresh_reason`).

Nothing is left behind and nothing waits forever:
- the handshake is acknowledged before the fork: the server answers "ok", the job's process
  answers "go", and only then is the copy forked (and "started" sent); a job process that died
  while queued never gets a copy;
- the copy gets a parent-death signal (SIGKILL when its supervisor dies, `prctl
  PR_SET_PDEATHSIG`) and checks its parent after setting it; the supervisor kills the copy when
  the job's process is gone;
- each read of the handshake, on both sides, is bounded (`HANDSHAKE_TIMEOUT_S`, or the
  `TACGEN_PRELOAD_TIMEOUT_S` variable): the server's loop never reads a client (a supervisor
  forked per connection does), and a job whose server does not answer in time runs fresh,
  logged;
- the copy's random state is a fresh interpreter's: Python's `random`, numpy's legacy global
  RandomState and torch's default CPU generator re-seeded from the OS.
  Python's string hash seed cannot be changed in a running interpreter: a job whose
  PYTHONHASHSEED differs from the server's runs fresh (a `PYTHON*` variable); where both leave
  it unset the copy's seed is random, as a fresh one's.
This module is the job's side (and what both sides share: the wire format, the variables);
the server's side is `tacgen_lib.runtime.preload_server`.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import sys
import time
from pathlib import Path
from typing import Any

__all__ = [
    "HANDSHAKE_TIMEOUT_S",
    "SOCKET_ENV",
    "benchmark_of_log",
    "fresh_reason",
    "interpreter_identity",
    "mark_job_copy",
    "receive_message",
    "run_in_preloaded_interpreter",
    "send_message",
    "usage_path",
]
#: The environment variable that carries the server's abstract socket name to the jobs.
SOCKET_ENV = "TACGEN_PRELOADED_INTERPRETER"
#: Set to 0 to run every job in a fresh interpreter.
SWITCH_ENV = "TACGEN_PRELOAD"

#: Environment variables a fresh interpreter or its imports read at start: by prefix. A job
#: whose values differ from the server's (as the server started) runs fresh (`preload_server._mismatch`).
IMPORT_TIME_PREFIXES = ("PYTHON", "LD_")
#: ... except these: the thread counts Snakemake sets per job, applied to the copy instead
#: (`preload_server._size_thread_pools`).
THREAD_VARIABLES = frozenset(
    {
        "OMP_NUM_THREADS",
        "GOTO_NUM_THREADS",
        "OPENBLAS_NUM_THREADS",
        "MKL_NUM_THREADS",
        "VECLIB_MAXIMUM_THREADS",
        "NUMEXPR_NUM_THREADS",
    }
)
#: Seconds each side waits for the other during the handshake (the server answers between two
#: imports: the longest, torch's, takes a few seconds on a loaded machine).
HANDSHAKE_TIMEOUT_S = 60.0
#: Overrides HANDSHAKE_TIMEOUT_S (seconds), on both sides.
TIMEOUT_ENV = "TACGEN_PRELOAD_TIMEOUT_S"
#: prctl(2)'s option number (linux/prctl.h).
_PR_SET_PDEATHSIG = 1
_fresh_reason: str | None = None  # the job's: why it runs in its own interpreter
#: what the job's process forwards to the job's copy
_FORWARDED = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
_MAX_REQUEST = 1 << 24
_worker = False  # True in the server's forked copies: a job runs its script there


def usage_path(benchmark: str | os.PathLike) -> Path:
    """The file beside a benchmark TSV that holds the resource usage of a job run in the
    preloaded interpreter: `<benchmark>.usage.json`."""
    p = Path(benchmark)
    return p.with_name(p.name + ".usage.json")


def benchmark_of_log(log: str | os.PathLike) -> Path:
    """A job's benchmark file from its log file, by the workflow's convention (checked for
    every rule by the workflow tests): `results/logs/<job>.log` ->
    `results/benchmarks/<job>.tsv`."""
    p = Path(log)
    parts = p.parts
    if "logs" not in parts or p.suffix != ".log":
        raise ValueError(f"{log}: not a results/logs/<job>.log path")
    i = len(parts) - 1 - parts[::-1].index("logs")
    return Path(*parts[:i], "benchmarks", *parts[i + 1 :]).with_suffix(".tsv")


def fresh_reason() -> str | None:
    """Why this job runs in its own interpreter although a preloaded one serves the run (None
    where it runs in the server, or no server serves the run). `tacgen_lib.io.log.for_rule`
    writes it into the rule's log."""
    return _fresh_reason


def interpreter_identity() -> dict[str, str]:
    """What makes an interpreter the same as another for a job: its real executable, its
    prefixes (a venv's or conda environment's) and its exact Python version."""
    return {
        "executable": os.path.realpath(sys.executable),
        "prefix": sys.prefix,
        "exec_prefix": sys.exec_prefix,
        "base_prefix": sys.base_prefix,
        "version": sys.version,
    }


def import_time_variables(env: dict[str, str]) -> dict[str, str]:
    """The variables of `env` a fresh interpreter and its imports read at start
    (`IMPORT_TIME_PREFIXES`), the thread counts aside."""
    return {
        k: v
        for k, v in env.items()
        if k.startswith(IMPORT_TIME_PREFIXES) and k not in THREAD_VARIABLES
    }


def handshake_timeout(env: dict[str, str] | None = None) -> float:
    """Seconds a handshake read waits: `TACGEN_PRELOAD_TIMEOUT_S` where set, else
    HANDSHAKE_TIMEOUT_S."""
    value = (os.environ if env is None else env).get(TIMEOUT_ENV, "")
    try:
        return float(value) if float(value) > 0 else HANDSHAKE_TIMEOUT_S
    except ValueError:
        return HANDSHAKE_TIMEOUT_S


def set_parent_death_signal(sig: int = signal.SIGKILL) -> None:
    """Have the kernel send `sig` to this process when the thread that forked it ends
    (prctl PR_SET_PDEATHSIG, Linux); OSError where the call fails."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
        errno = ctypes.get_errno()
        raise OSError(errno, f"prctl(PR_SET_PDEATHSIG): {os.strerror(errno)}")


def mark_job_copy() -> None:
    """Mark this process as a job's copy forked by the server
    (`tacgen_lib.runtime.preload_server`): its script's `run_in_preloaded_interpreter` returns
    at once."""
    global _worker
    _worker = True


# ---------------------------------------------------------------- the job's side (client)


def send_message(sock: socket.socket, payload: bytes) -> None:
    """One message of the handshake: its length (4 bytes, network order), then its bytes."""
    sock.sendall(struct.pack("!I", len(payload)) + payload)


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    chunks, got = [], 0
    while got < n:
        chunk = sock.recv(n - got)
        if not chunk:
            raise ConnectionError("preloaded interpreter: connection closed")
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


def receive_message(sock: socket.socket) -> bytes:
    """One message sent by `send_message` (ConnectionError where the peer is gone, or a
    message is over 16 MiB)."""
    (n,) = struct.unpack("!I", _recv_exact(sock, 4))
    if n > _MAX_REQUEST:
        raise ConnectionError(f"preloaded interpreter: message of {n} bytes")
    return _recv_exact(sock, n)


def _usage_file(snakemake: Any) -> Path | None:
    logs = list(getattr(snakemake, "log", []) or [])
    if not logs:
        return None
    try:
        return usage_path(benchmark_of_log(logs[0]))
    except ValueError:
        return None


def run_in_preloaded_interpreter(snakemake: Any) -> None:
    """Run this script job in the preloaded interpreter, if one serves this run, and exit with
    its status; else return at once and the script runs here (`fresh_reason` says why, where
    a server serves the run). Called first by every workflow script (before its imports), with
    the `snakemake` object of the `script:` directive."""
    global _fresh_reason
    if _worker:
        return
    usage = _usage_file(snakemake)
    if usage is not None:
        usage.unlink(missing_ok=True)  # a stale one from an earlier run in a server
    name = os.environ.get(SOCKET_ENV)
    if not name or os.environ.get(SWITCH_ENV) == "0":
        return
    timeout = handshake_timeout()
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(timeout)
    try:
        sock.connect("\0" + name)
    except OSError as err:
        sock.close()
        _fresh_reason = f"no preloaded interpreter listens ({err})"
        return  # no server (yet, or any more): run here
    script = os.path.abspath(sys.argv[0])
    # signals this process ignores (inherited: a fresh interpreter keeps ignoring them, even
    # SIGINT): the job's copy ignores them too, and they are not forwarded
    ignored = [int(s) for s in _FORWARDED if signal.getsignal(s) == signal.SIG_IGN]
    request = json.dumps(
        {
            "script": script,
            "cwd": os.getcwd(),
            "env": dict(os.environ),
            "ignored": ignored,
            "interpreter": interpreter_identity(),
        }
    )
    try:
        # 1. the request; 2. "ok" or "fresh <why>"; 3. "go": only now does the server fork
        #    the copy; 4. "started" once it has
        socket.send_fds(sock, [b"R"], [0, 1, 2])
        send_message(sock, request.encode())
        answer = receive_message(sock)
        if answer == b"ok":
            send_message(sock, b"go")
            answer = receive_message(sock)
    except TimeoutError:
        sock.close()  # a copy forked after all is killed by its supervisor on this close
        _fresh_reason = f"the preloaded interpreter did not answer within {timeout:g} s"
        return
    except OSError as err:
        sock.close()
        _fresh_reason = f"the preloaded interpreter went away before the job started ({err})"
        return
    if answer != b"started":
        sock.close()
        _fresh_reason = answer.decode(errors="replace").removeprefix("fresh ")
        return
    sock.settimeout(None)  # the job runs as long as it runs
    started = time.monotonic()

    def forward(signum: int, _frame: object) -> None:
        try:
            send_message(sock, str(signum).encode())
        except OSError:
            pass

    for s in _FORWARDED:
        if int(s) not in ignored:
            signal.signal(s, forward)
    while True:
        try:
            result = json.loads(receive_message(sock))
            break
        except InterruptedError:
            continue
        except (OSError, ValueError) as err:
            print(f"preloaded interpreter: lost the job's process: {err}", file=sys.stderr)
            os._exit(1)
    sock.close()
    if usage is not None and result.get("exitcode") == 0:
        result["wall_s"] = time.monotonic() - started
        usage.parent.mkdir(parents=True, exist_ok=True)
        tmp = usage.with_name(usage.name + ".tmp")
        tmp.write_text(json.dumps(result, sort_keys=True))
        os.replace(tmp, usage)
    sys.stdout.flush()
    sys.stderr.flush()
    if result.get("signal"):
        sig = int(result["signal"])
        signal.signal(sig, signal.SIG_DFL)
        os.kill(os.getpid(), sig)
    os._exit(int(result.get("exitcode", 1)))
