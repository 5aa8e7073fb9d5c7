"""The preloaded interpreter's server (`tacgen_lib.runtime.preload` describes it and holds the
job's side): started per local Snakemake process (`start_preloaded_interpreter`, the
Snakefile's `onstart`), it listens on an abstract Unix socket, imports `PRELOADED_MODULES`
and forks, per job, a supervisor that does the handshake (`_handshake`), then the job's copy
that runs the script as a fresh interpreter would (`_run_job`).
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

from tacgen_lib.runtime.preload import (
    SOCKET_ENV,
    SWITCH_ENV,
    handshake_timeout,
    import_time_variables,
    interpreter_identity,
    mark_job_copy,
    receive_message,
    send_message,
    set_parent_death_signal,
)

__all__ = [
    "ENVIRONMENT_PRELOADS",
    "MIN_JOBS",
    "PRELOADED_MODULES",
    "serve",
    "start_preloaded_interpreter",
    "stop_preloaded_interpreter",
]

#: What the server imports, in this order: third-party libraries whose import does not depend
#: on a job's environment (mujoco's does: `ENVIRONMENT_PRELOADS`), not the workflow's own
#: modules (a job imports them as it would fresh). First most of what a run's first jobs import
#: (the simulator's: corpus shards and demonstrations), then the heavy rest (scikit-learn,
#: torch, matplotlib), which the jobs that need it come after. Between two imports the server
#: forks the jobs waiting for it (`serve`). mujoco comes last: imported before scikit-learn and
#: torch, beside OpenCV, it made every later scikit-learn fit in the copies slower (a tiny
#: Ridge took many times its CPU time: the OpenMP and BLAS libraries load in another order), so the simulator's first jobs import it themselves.
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
_start_env: dict[str, str] = {}  # the server's import-time variables as it started (`serve`)


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


def _reseed_as_fresh() -> None:
    """The random state a fresh interpreter starts with, in a copy that inherited the server's:
    Python's `random`, numpy's legacy global RandomState and torch's default CPU generator
    seeded from the OS, as each is at its import (a fresh torch's initial seed is random too;
    the workflow's code seeds its own generators)."""
    import random

    random.seed()
    numpy = sys.modules.get("numpy")
    if numpy is not None:
        numpy.random.seed()
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.default_generator.seed()


def _run_job(request: dict, fds: list[int], supervisor: int) -> None:
    """In the forked copy: die with the `supervisor` that forked it, become the job (streams,
    directory, environment, threads, random state) and run its script as `__main__`; never
    returns."""
    mark_job_copy()
    code = 1
    interrupted = False
    try:
        # killed with its supervisor (even by SIGKILL); one that died before this line is seen
        # by the parent check
        set_parent_death_signal(signal.SIGKILL)
        if os.getppid() != supervisor:
            os._exit(1)
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
        _reseed_as_fresh()
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


def _handshake(conn: socket.socket) -> tuple[dict, list[int]] | None:
    """The supervisor's half of the handshake, every read bounded by `handshake_timeout`: the
    job's streams and request, "ok" or "fresh <why>", the job's "go". The request and the
    job's streams where the job may start, else None (streams closed)."""
    conn.settimeout(handshake_timeout())
    fds: list[int] = []
    try:
        if _peer_uid(conn) != os.getuid():
            raise ConnectionError("another user")
        _, fds, _, _ = socket.recv_fds(conn, 1, _RECV_FDS)
        if len(fds) != _RECV_FDS:
            raise ConnectionError("no streams")
        request = json.loads(receive_message(conn))
        why = _mismatch(request)
        if why is not None:
            send_message(conn, b"fresh " + why.encode())
            raise ConnectionError(why)
        send_message(conn, b"ok")
        if receive_message(conn) != b"go":
            raise ConnectionError("no acknowledgement")
    except (OSError, ValueError, KeyError, TypeError):
        for fd in fds:
            os.close(fd)
        return None
    return request, fds


def _supervise(conn: socket.socket) -> None:
    """In the copy the server forks per connection: the handshake (`_handshake`), then fork the
    job, forward signals from the job's process, kill the job if that process dies, report
    status and usage; never returns."""
    code = 1
    try:
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        accepted = _handshake(conn)
        if accepted is None:
            os._exit(0)
        request, fds = accepted
        start = time.monotonic()
        supervisor = os.getpid()
        pid = os.fork()
        if pid == 0:
            conn.close()
            _run_job(request, fds, supervisor)
        for fd in fds:
            os.close(fd)
        pidfd = os.pidfd_open(pid)
        try:
            send_message(conn, b"started")
        except OSError:
            os.kill(pid, signal.SIGKILL)  # the job's process is gone (it timed out and left)
        conn.settimeout(None)
        result: dict[str, Any] | None = None
        while result is None:
            ready, _, _ = select.select([pidfd, conn], [], [])
            if conn in ready:
                try:
                    msg = receive_message(conn)
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
            send_message(conn, json.dumps(result).encode())
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


def _mismatch(request: dict) -> str | None:
    """Why the job of `request` must run in its own interpreter, or None where a fresh one would
    be the server's: the interpreter (`interpreter_identity`), the import-time variables
    (`import_time_variables`, against the server's as it started) and the variables of
    `ENVIRONMENT_PRELOADS` (their defaults where unset, in any case)."""
    theirs = request.get("interpreter") or {}
    ours = interpreter_identity()
    for key, value in ours.items():
        if theirs.get(key) != value:
            return (
                f"another interpreter: its {key} is {theirs.get(key)!r}, the preloaded "
                f"interpreter's {value!r}"
            )
    env = request["env"]
    job = import_time_variables(env)
    for key in sorted(set(job) | set(_start_env)):
        if job.get(key) != _start_env.get(key):
            return (
                f"another environment: {key} is {job.get(key)!r} for the job, "
                f"{_start_env.get(key)!r} for the preloaded interpreter"
            )
    defaults = {k: d for _module, variables in ENVIRONMENT_PRELOADS for k, d in variables}
    for key, value in _preload_env.items():
        if env.get(key, defaults[key]).lower().strip() != value.lower().strip():
            return (
                f"another OpenGL backend: {key} is {env.get(key, defaults[key])!r} for the job, "
                f"mujoco was preloaded with {value!r}"
            )
    return None


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
    _start_env.update(import_time_variables(dict(os.environ)))  # before any import sets one
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind("\0" + name)
    listener.listen(64)
    # a terminal's Ctrl-C reaches the whole process group: the jobs' copies take it (as fresh
    # interpreters would), the server and the copies' supervisors carry on until Snakemake ends
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    pending = list(PRELOADED_MODULES)
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
        # the loop never reads a client: a supervisor per connection does the (time-bounded)
        # handshake, so one stalled client holds up no other job
        if os.fork() == 0:
            listener.close()
            _supervise(conn)
        conn.close()


_SERVER = (
    "import sys; from tacgen_lib.runtime.preload_server import serve; "
    "serve(sys.argv[1], int(sys.argv[2]))"
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
