"""A preloaded interpreter for the workflow's script jobs: a fork server.

Most jobs of a small config are start-up: a fresh interpreter importing torch, scikit-learn,
scipy and pandas spends 1-3 CPU-seconds before its first line of work, longer than many jobs'
work. On a local run (`snakemake --cores N`, never on a cluster executor) the Snakefile's
`onstart` starts one server per Snakemake process (`start_preloaded_interpreter`): it imports
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
the job (its environment would import mujoco for another OpenGL backend:
`ENVIRONMENT_PRELOADS`), the job runs in its own interpreter: the server only ever saves
start-up time. `TACGEN_PRELOAD=0` turns it off.
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import struct
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Any

__all__ = [
    "PRELOADED_MODULES",
    "SOCKET_ENV",
    "benchmark_of_log",
    "run_in_preloaded_interpreter",
    "serve",
    "start_preloaded_interpreter",
    "stop_preloaded_interpreter",
    "usage_path",
]

#: The environment variable that carries the server's abstract socket name to the jobs.
SOCKET_ENV = "TACGEN_PRELOADED_INTERPRETER"
#: Set to 0 to run every job in a fresh interpreter.
SWITCH_ENV = "TACGEN_PRELOAD"

#: What the server imports, in this order: third-party libraries whose import does not depend
#: on a job's environment (mujoco's does: `ENVIRONMENT_PRELOADS`), not the workflow's own
#: modules (a job imports them as it would fresh). First most of what a run's first jobs import
#: (the simulator's: corpus shards and demonstrations), then the heavy rest (scikit-learn,
#: torch, matplotlib), which the jobs that need it come after. Between two imports the server
#: forks the jobs waiting for it (`serve`). mujoco comes last: imported before scikit-learn and
#: torch, beside OpenCV, it made every later scikit-learn fit in the copies slower (a 5x5
#: Ridge: 0.26 against 0.02 CPU-s, measured; the OpenMP and BLAS libraries load in another
#: order), so the simulator's first jobs import it themselves.
PRELOADED_MODULES = (
    "numpy",
    "threadpoolctl",
    "pandas",
    "pyarrow.parquet",
    "scipy.special",
    "cv2",
    "yaml",
    "snakemake.io",
    "snakemake.iocontainers",
    "snakemake.logging",
    "scipy.stats",
    "scipy.ndimage",
    "scipy.optimize",
    "sklearn.linear_model",
    "sklearn.model_selection",
    "sklearn.metrics",
    "sklearn.preprocessing",
    "sklearn.decomposition",
    "torch",
    "torch.nn.functional",
    "safetensors.torch",
    "matplotlib.pyplot",
    "mujoco",
)

#: Preloaded modules whose import depends on environment variables: (module, ((variable, the
#: value it has where unset), ...)). mujoco picks its OpenGL backend from MUJOCO_GL when
#: imported (`tacgen_lib.corpus.sim` defaults it to egl first: headless EGL), and its EGL
#: backend needs PYOPENGL_PLATFORM unset or egl (it sets egl). The server imports mujoco with
#: MUJOCO_GL defaulted the same way; a job whose environment gives either variable another
#: value is declined and runs in its own interpreter (`_environment_fits`).
ENVIRONMENT_PRELOADS = (("mujoco", (("MUJOCO_GL", "egl"), ("PYOPENGL_PLATFORM", "egl"))),)

_RECV_FDS = 3  # the job's stdin, stdout and stderr
_preload_env: dict[str, str] = {}  # the server's: {variable: value} its imports were made with
_import_env: dict[str, str] = {}  # the server's: variables its imports set (KMP_*, ...)
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


# ---------------------------------------------------------------- the job's side (client)


def _send(sock: socket.socket, payload: bytes) -> None:
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


def _recv(sock: socket.socket) -> bytes:
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
    its status; else return at once and the script runs here. Called first by every workflow
    script (before its imports), with the `snakemake` object of the `script:` directive."""
    if _worker:
        return
    usage = _usage_file(snakemake)
    if usage is not None:
        usage.unlink(missing_ok=True)  # a stale one from an earlier run in a server
    name = os.environ.get(SOCKET_ENV)
    if not name or os.environ.get(SWITCH_ENV) == "0":
        return
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect("\0" + name)
    except OSError:
        sock.close()
        return  # no server (yet): run here
    script = os.path.abspath(sys.argv[0])
    # signals this process ignores (inherited: a fresh interpreter keeps ignoring them, even
    # SIGINT): the job's copy ignores them too, and they are not forwarded
    ignored = [int(s) for s in _FORWARDED if signal.getsignal(s) == signal.SIG_IGN]
    request = json.dumps(
        {"script": script, "cwd": os.getcwd(), "env": dict(os.environ), "ignored": ignored}
    )
    try:
        socket.send_fds(sock, [b"R"], [0, 1, 2])
        _send(sock, request.encode())
        accepted = _recv(sock)
    except OSError:
        sock.close()
        return  # the server went away before it took the job: run here
    if accepted != b"ok":
        sock.close()
        return
    started = time.monotonic()

    def forward(signum: int, _frame: object) -> None:
        try:
            _send(sock, str(signum).encode())
        except OSError:
            pass

    for s in _FORWARDED:
        if int(s) not in ignored:
            signal.signal(s, forward)
    while True:
        try:
            result = json.loads(_recv(sock))
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


# ---------------------------------------------------------------- the server's side


def _size_thread_pools(env: dict[str, str]) -> None:
    """Size OpenMP, BLAS and torch pools as a fresh interpreter with this environment would
    have them (Snakemake sets OMP_NUM_THREADS and the BLAS variables to the job's threads).
    Only the libraries the server had loaded before the fork: one loaded later, by the job,
    reads the variables itself."""
    from threadpoolctl import threadpool_limits

    limits: dict[str, int] = {}
    if env.get("OMP_NUM_THREADS", "").isdigit():
        limits["openmp"] = int(env["OMP_NUM_THREADS"])
    blas = env.get("OPENBLAS_NUM_THREADS") or env.get("MKL_NUM_THREADS")
    if blas and blas.isdigit():
        limits["blas"] = int(blas)
    if limits:
        threadpool_limits(limits=limits)
    torch = sys.modules.get("torch")
    if "openmp" in limits and torch is not None:
        torch.set_num_threads(limits["openmp"])


def _run_job(request: dict, fds: list[int]) -> None:
    """In the forked copy: become the job (streams, directory, environment, threads) and run
    its script as `__main__`; never returns."""
    global _worker
    _worker = True
    code = 1
    interrupted = False
    try:
        # a fresh interpreter's dispositions (the server ignores SIGINT), or the job process's
        # where it ignores a signal
        signal.signal(signal.SIGINT, signal.default_int_handler)
        for s in (signal.SIGTERM, signal.SIGHUP):
            signal.signal(s, signal.SIG_DFL)
        for s in request.get("ignored", ()):
            signal.signal(s, signal.SIG_IGN)
        for target, fd in enumerate(fds):
            os.dup2(fd, target)
            os.close(fd)
        os.chdir(request["cwd"])
        os.environ.clear()
        os.environ.update(request["env"])
        for key, value in _import_env.items():  # as the imports would have set them fresh
            os.environ.setdefault(key, value)
        _size_thread_pools(request["env"])
        sys.argv = [request["script"]]
        sys.path.insert(0, os.path.dirname(request["script"]))  # as `python script.py` does
        import runpy

        try:
            runpy.run_path(request["script"], run_name="__main__")
            code = 0
        except SystemExit as exit_:
            c = exit_.code
            code = c if isinstance(c, int) else (0 if c is None else 1)
            if c is not None and not isinstance(c, int):
                print(c, file=sys.stderr)
        except BaseException as err:
            # what the interpreter does with an unhandled exception: the script's own hook
            # (tacgen_lib.io.log writes the failure into the rule's log) and the traceback
            sys.excepthook(type(err), err, err.__traceback__)
            code = 1
            interrupted = isinstance(err, KeyboardInterrupt)
        import atexit

        atexit._run_exitfuncs()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
            if interrupted:  # as a fresh interpreter ends on an unhandled KeyboardInterrupt
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                os.kill(os.getpid(), signal.SIGINT)
        finally:
            os._exit(code)


def _supervise(conn: socket.socket, request: dict, fds: list[int]) -> None:
    """In the forked copy that holds the job's connection: fork the job, forward signals from
    the job's process, kill the job if that process dies, report status and usage; never
    returns."""
    code = 1
    try:
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        start = time.monotonic()
        pid = os.fork()
        if pid == 0:
            conn.close()
            _run_job(request, fds)
        for fd in fds:
            os.close(fd)
        pidfd = os.pidfd_open(pid)
        _send(conn, b"ok")
        result: dict[str, Any] | None = None
        while result is None:
            ready, _, _ = select.select([pidfd, conn], [], [])
            if conn in ready:
                try:
                    msg = _recv(conn)
                    os.kill(pid, int(msg))
                except (ConnectionError, OSError, ValueError):
                    os.kill(pid, signal.SIGKILL)  # the job's process is gone
            if pidfd in ready or conn in ready:
                got, status, ru = os.wait4(pid, os.WNOHANG)
                if got == pid:
                    result = {
                        "exitcode": os.waitstatus_to_exitcode(status),
                        "signal": os.WTERMSIG(status) if os.WIFSIGNALED(status) else 0,
                        "cpu_s": ru.ru_utime + ru.ru_stime,
                        "max_rss_mb": ru.ru_maxrss / 1024.0,
                        "job_wall_s": time.monotonic() - start,
                        "pid": pid,
                    }
        try:
            _send(conn, json.dumps(result).encode())
        except OSError:
            pass
        code = 0
    finally:
        os._exit(code)


def _peer_uid(conn: socket.socket) -> int:
    creds = conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    return struct.unpack("3i", creds)[1]


def _preload(module: str) -> None:
    """Import `module` in the server as a job would: matplotlib with the Agg backend the
    workflow's figures use (tacgen_lib.report); an `ENVIRONMENT_PRELOADS` module with MUJOCO_GL
    defaulted as the workflow's code defaults it, remembering the values it was imported with
    (`_preload_env`). What an import sets in the environment itself is remembered too
    (`_import_env`: scikit-learn's KMP_* settings, mujoco's PYOPENGL_PLATFORM): a copy's
    environment gets them as a fresh interpreter's would (`_run_job`)."""
    import importlib

    if module == "matplotlib.pyplot":
        import matplotlib

        matplotlib.use("Agg")
    for name, variables in ENVIRONMENT_PRELOADS:
        if name == module:
            first, default = variables[0]
            os.environ.setdefault(first, default)
            _preload_env.update({k: os.environ.get(k, d) for k, d in variables})
    before = dict(os.environ)
    importlib.import_module(module)
    _import_env.update({k: v for k, v in os.environ.items() if before.get(k) != v})


def _environment_fits(env: dict[str, str]) -> bool:
    """Whether a job with environment `env` would have imported `ENVIRONMENT_PRELOADS` as the
    server did: each of their variables (its default where unset) equal, in any case."""
    defaults = {k: d for _module, variables in ENVIRONMENT_PRELOADS for k, d in variables}
    return all(
        env.get(k, defaults[k]).lower().strip() == v.lower().strip()
        for k, v in _preload_env.items()
    )


def _reap() -> None:
    """Collect the copies that have exited (while the server still imports, SIGCHLD is not
    ignored: an import may wait for a subprocess of its own)."""
    while True:
        try:
            pid, _status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return


def serve(name: str, parent: int) -> None:
    """The server: listen on the abstract socket `name`, import `PRELOADED_MODULES`, fork a
    copy per job; exit when the process `parent` (Snakemake) is gone. Jobs may only come from
    this user. The socket listens before the imports, and between two imports the server forks
    the jobs already waiting: a run's first jobs start once what they import is loaded (the
    modules come in the order they need them) instead of waiting for all of it, and a job
    forked early imports what is still missing itself, as a fresh interpreter would."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind("\0" + name)
    listener.listen(64)
    # a terminal's Ctrl-C reaches the whole process group: the jobs' copies take it (as fresh
    # interpreters would), the server and the copies' supervisors carry on until Snakemake ends
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    pending = list(PRELOADED_MODULES)
    uid = os.getuid()
    while os.getppid() == parent:
        ready, _, _ = select.select([listener], [], [], 0 if pending else 1.0)
        if not ready:
            if pending:
                _preload(pending.pop(0))
                _reap()
                if not pending:
                    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # the kernel reaps copies
            continue
        conn, _ = listener.accept()
        fds: list[int] = []
        try:
            if _peer_uid(conn) != uid:
                raise ConnectionError("another user")
            _, fds, _, _ = socket.recv_fds(conn, 1, _RECV_FDS)
            if len(fds) != _RECV_FDS:
                raise ConnectionError("no streams")
            request = json.loads(_recv(conn))
            if not _environment_fits(request["env"]):
                _send(conn, b"fresh")  # the job runs in its own interpreter
                raise ConnectionError("another environment")
        except (OSError, ValueError, KeyError):
            for fd in fds:
                os.close(fd)
            conn.close()
            continue
        if os.fork() == 0:
            listener.close()
            _supervise(conn, request, fds)
        for fd in fds:
            os.close(fd)
        conn.close()


_SERVER = (
    "import sys; from tacgen_lib.runtime.preload import serve; serve(sys.argv[1], int(sys.argv[2]))"
)


#: Fewest jobs a run needs for the server to pay: its imports cost ~3-4.5 CPU-seconds, which
#: the first jobs wait for (a run of six short jobs measured none served when they did not).
MIN_JOBS = 8
#: Seconds `start_preloaded_interpreter` waits at most for the server's socket to listen.
BIND_WAIT_S = 5.0


def start_preloaded_interpreter(
    jobs: int = MIN_JOBS, *, local: bool = True
) -> subprocess.Popen | None:
    """Start the server for this Snakemake process (the Snakefile's `onstart`) and tell its
    jobs where it listens (the `SOCKET_ENV` variable, inherited by every job). None, and no
    variable, for a cluster executor (`local` False), `TACGEN_PRELOAD=0` or a run of fewer than
    `MIN_JOBS` jobs: a variable inherited from an enclosing run (Snakemake started inside a job)
    is removed, so this run's jobs never use another run's server."""
    os.environ.pop(SOCKET_ENV, None)
    if not local or os.environ.get(SWITCH_ENV) == "0" or jobs < MIN_JOBS:
        return None
    name = f"tacgen-preload-{os.getpid()}-{uuid.uuid4().hex}"
    proc = subprocess.Popen(
        # -P: no working directory on sys.path, so the server imports this module (and the jobs
        # the workflow's code) from where a job's fresh interpreter would
        [sys.executable, "-P", "-c", _SERVER, name, str(os.getpid())],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
    )
    os.environ[SOCKET_ENV] = name
    # the socket listens before the server's imports (`serve`): once it does, a job queues
    # for the server instead of running fresh; a server that has not bound it within the
    # wait still serves the jobs that come later
    deadline = time.monotonic() + BIND_WAIT_S
    while not _listening(name) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    return proc


def _listening(name: str) -> bool:
    """Whether the abstract Unix socket `name` is bound (Linux: /proc/net/unix)."""
    try:
        table = Path("/proc/net/unix").read_text()
    except OSError:
        return True  # cannot tell: do not wait
    return f" @{name}\n" in table or table.endswith(f" @{name}")


def stop_preloaded_interpreter(proc: subprocess.Popen | None) -> None:
    """Stop the server (the Snakefile's `onsuccess` / `onerror`); its running copies finish."""
    os.environ.pop(SOCKET_ENV, None)
    if proc is not None and proc.poll() is None:
        proc.terminate()
        proc.wait()
