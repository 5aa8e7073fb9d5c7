"""The preloaded interpreter (tacgen_lib.runtime.preload): a job forked from the server behaves
as the same script in a fresh interpreter (environment, directory, streams, thread pools,
results, exit status, signals), its usage lands beside its benchmark, and nothing outlives
what it belongs to. The workflow-level check (every edge of a run equal with and without the
server) is in the workflow tests' determinism test: the reference run uses the server."""

from __future__ import annotations

import ast
import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
import uuid
from pathlib import Path

import pytest

from tacgen_lib.runtime import preload, preload_server
from tacgen_lib.runtime.benchmarks import read_benchmark

ROOT = Path(__file__).resolve().parents[2]
LOG = "results/logs/rule_x/a/1.log"
BENCH = "results/benchmarks/rule_x/a/1.tsv"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    stat = Path(f"/proc/{pid}/stat")
    return stat.exists() and stat.read_text().split(") ")[1][0] != "Z"


def _wait_until(predicate, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return predicate()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A server of this test process, as the Snakefile's onstart starts one for Snakemake."""
    name = f"tacgen-test-{os.getpid()}-{uuid.uuid4().hex}"
    proc = subprocess.Popen(
        [sys.executable, "-P", "-c", preload_server._SERVER, name, str(os.getpid())]
    )

    def listening() -> bool:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            try:
                s.connect("\0" + name)
            except OSError:
                return False
            return True

    assert _wait_until(listening, 120), "the server did not start listening"
    # the server serves jobs while it still imports: the tests want a copy of the whole
    # preloaded interpreter, so wait until a job finds every module loaded
    probe = job_script(tmp_path_factory.mktemp("probe"), "print(preloaded)")
    assert _wait_until(lambda: run_job(probe, env_for(name)).stdout.strip() == "True", 120)
    yield name
    proc.terminate()
    proc.wait(timeout=30)


def job_script(tmp_path: Path, body: str, log: str | None = LOG) -> Path:
    """A script as Snakemake's `script:` directive runs it: a `snakemake` object (its log
    list), then the workflow scripts' first two lines, then `body`."""
    script = tmp_path / ".snakemake" / "scripts" / f"tmp{uuid.uuid4().hex[:8]}.job.py"
    script.parent.mkdir(parents=True, exist_ok=True)
    logs = [log] if log else []
    script.write_text(
        "import types\n"
        f"snakemake = types.SimpleNamespace(log={logs!r}, rule='rule_x', wildcards={{}})\n"
        "import sys\n"
        f"preloaded = all(m in sys.modules for m in {preload_server.PRELOADED_MODULES!r})\n"
        "from tacgen_lib.runtime.preload import run_in_preloaded_interpreter\n"
        "run_in_preloaded_interpreter(snakemake)\n" + textwrap.dedent(body)
    )
    return script


def env_for(name: str | None, threads: int = 1, **extra: str) -> dict[str, str]:
    """The environment Snakemake gives a job of `threads` threads (shell.py), and the server's
    name if one serves the run."""
    env = {k: v for k, v in os.environ.items() if k != preload.SOCKET_ENV}
    for var in ("OMP_NUM_THREADS", "GOTO_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env[var] = str(threads)
    if name:
        env[preload.SOCKET_ENV] = name
    return {**env, **extra}


def run_job(script: Path, env: dict[str, str], timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(script)],
        cwd=script.parents[2],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


REPORT = """
import json, os, torch
from threadpoolctl import threadpool_info
print(json.dumps({
    "pid": os.getpid(), "preloaded": preloaded, "cwd": os.getcwd(), "argv": sys.argv,
    "mark": os.environ.get("MARK"), "torch_threads": torch.get_num_threads(),
    "pools": sorted({(p["user_api"], p["num_threads"]) for p in threadpool_info()}),
    "path0": sys.path[0], "name": __name__,
}))
print("to stderr", file=sys.stderr)
"""


@pytest.mark.parametrize("threads", [1, 2])
def test_a_job_in_the_server_sees_what_a_fresh_interpreter_gives_it(server, tmp_path, threads):
    script = job_script(tmp_path, REPORT)
    fresh = run_job(script, env_for(None, threads, MARK="m"))
    forked = run_job(script, env_for(server, threads, MARK="m"))
    assert fresh.returncode == forked.returncode == 0, (fresh.stderr, forked.stderr)
    a, b = json.loads(fresh.stdout), json.loads(forked.stdout)
    # where it ran: not preloaded in its own process, preloaded in the server's copy
    assert (a["preloaded"], b["preloaded"]) == (False, True)
    assert a["pid"] != b["pid"]
    # what it sees is the same: directory, argv, environment, thread pools, sys.path[0]
    for key in ("cwd", "argv", "mark", "torch_threads", "pools", "path0", "name"):
        assert a[key] == b[key], key
    assert a["torch_threads"] == threads
    assert all(n == threads for _, n in map(tuple, b["pools"]))
    assert forked.stderr.strip() == fresh.stderr.strip() == "to stderr"


def test_results_are_bit_identical_to_a_fresh_interpreter(server, tmp_path):
    """The same computation (same code, data, thread counts, machine) in both: bit identity is
    the right assertion."""
    body = """
    import hashlib, numpy as np, torch
    from sklearn.linear_model import Ridge
    torch.manual_seed(0)
    x = torch.randn(300, 200, dtype=torch.float32)
    y = (x @ x.T).tanh().sum(1)
    rng = np.random.default_rng(0)
    a = rng.normal(size=(400, 50))
    coef = Ridge(alpha=1.0).fit(a, a @ rng.normal(size=50)).coef_
    h = hashlib.sha256(y.numpy().tobytes() + coef.tobytes() + np.linalg.svd(a)[1].tobytes())
    print(h.hexdigest())
    """
    script = job_script(tmp_path, body)
    # two threads: the pools the server sized after the fork do the work
    fresh = run_job(script, env_for(None, 2))
    forked = run_job(script, env_for(server, 2))
    assert fresh.returncode == forked.returncode == 0, forked.stderr
    assert fresh.stdout == forked.stdout


RENDER = """
import hashlib
import tacgen_lib.corpus.sim  # defaults MUJOCO_GL to egl before mujoco, as the simulator does
import mujoco
from mujoco.rendering.classic import gl_context
model = mujoco.MjModel.from_xml_string(
    "<mujoco><worldbody><light pos='0 0 2'/><geom type='sphere' size='0.1' rgba='1 0 0 1'/>"
    "</worldbody></mujoco>"
)
data = mujoco.MjData(model)
mujoco.mj_forward(model, data)
with mujoco.Renderer(model, 24, 32) as renderer:
    renderer.update_scene(data)
    frame = renderer.render()
print(preloaded, gl_context.GLContext.__module__, os.environ.get("MUJOCO_GL"),
      os.environ.get("PYOPENGL_PLATFORM"), hashlib.sha256(frame.tobytes()).hexdigest())
"""


def test_mujoco_is_preloaded_with_the_simulators_backend_and_renders_the_same_frame(
    server, tmp_path
):
    """mujoco is imported by the server as the simulator's jobs import it (EGL): same backend,
    same environment afterwards, the same frame bit for bit (same computation, same machine)."""
    script = job_script(tmp_path, "import os\n" + RENDER)
    fresh = run_job(script, env_for(None))
    forked = run_job(script, env_for(server))
    assert fresh.returncode == forked.returncode == 0, (fresh.stderr, forked.stderr)
    a, b = fresh.stdout.split(), forked.stdout.split()
    assert (a[0], b[0]) == ("False", "True")
    assert a[1:] == b[1:] and a[1:4] == ["mujoco.egl", "egl", "egl"], (a, b)


@pytest.mark.parametrize("variable", ["MUJOCO_GL", "PYOPENGL_PLATFORM"])
def test_a_job_asking_for_another_gl_backend_runs_in_its_own_interpreter(
    server, tmp_path, variable
):
    """The server imported mujoco for EGL: a job whose environment picks OSMesa is declined
    (it runs, in a fresh interpreter, with what it asked for)."""
    script = job_script(tmp_path, "print(preloaded)")
    declined = run_job(script, env_for(server, **{variable: "osmesa"}))
    assert (declined.returncode, declined.stdout.strip()) == (0, "False"), declined.stderr
    # the same backend in any case, and another value of what an import sets itself
    # (scikit-learn's KMP_*): served
    other = {"KMP_INIT_AT_FORK": "TRUE"}
    served = run_job(script, env_for(server, MUJOCO_GL="EGL", **other))
    assert (served.returncode, served.stdout.strip()) == (0, "True"), served.stderr


def test_a_job_waiting_while_the_server_imports_is_forked_between_two_imports(tmp_path):
    """A job that comes while the server imports is forked after the import under way, not
    after all of them, and imports what is still missing itself. Two stand-in modules make
    the order deterministic: the job starts once the server imports `first`, which returns
    only once the job is queued; `second` returns only once the job has finished."""
    (tmp_path / "lib").mkdir()
    started, queued, done = tmp_path / "started", tmp_path / "queued", tmp_path / "done"
    for module, gate in (("first", queued), ("second", done)):
        (tmp_path / "lib" / f"{module}.py").write_text(
            f"import os, pathlib, time\npathlib.Path({str(started)!r}).touch()\n"
            f"while not os.path.exists({str(gate)!r}):\n    time.sleep(0.02)\n"
        )
    name = f"tacgen-test-{os.getpid()}-{uuid.uuid4().hex}"
    code = (
        f"import sys; sys.path.insert(0, {str(tmp_path / 'lib')!r})\n"
        "from tacgen_lib.runtime import preload_server\n"
        "preload_server.PRELOADED_MODULES = ('numpy', 'first', 'second')\n"
        f"preload_server.serve({name!r}, {os.getpid()})"
    )
    server = subprocess.Popen([sys.executable, "-P", "-c", code])
    try:
        body = """
        from tacgen_lib.runtime import preload
        loaded = [m in sys.modules for m in ("numpy", "first", "second")]
        import second  # what the server has not imported yet: the job imports it, fresh
        print(preload._worker, loaded)
        """
        script = job_script(tmp_path, "import sys\n" + textwrap.dedent(body))
        assert _wait_until(started.exists, 60), "the server did not reach `first`"
        proc = _start(script, env_for(name))
        # the job is queued on the socket while the server imports `first`
        assert _wait_until(lambda: _queued_on(name), 60), "the job never reached the server"
        queued.touch()
        # forked after `first`, the job imports `second` itself: it cannot end before `done`
        assert not _wait_until(lambda: proc.poll() is not None, 0.5)
        done.touch()
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err
        assert out.strip() == "True [True, True, False]", out + err
    finally:
        queued.touch()
        done.touch()
        server.terminate()
        server.wait(timeout=30)


def _queued_on(name: str) -> bool:
    """Whether a connection waits on the abstract socket `name` (Linux /proc/net/unix: the
    listening socket's receive queue is not shown, a connected peer is)."""
    table = Path("/proc/net/unix").read_text().splitlines()
    return sum(line.endswith(f" @{name}") for line in table) >= 2


def test_exit_status_and_traceback_come_back(server, tmp_path):
    exits = run_job(job_script(tmp_path, "sys.exit(3)"), env_for(server))
    assert exits.returncode == 3
    message = run_job(job_script(tmp_path, "sys.exit('no input')"), env_for(server))
    assert message.returncode == 1 and "no input" in message.stderr
    raises = run_job(job_script(tmp_path, "raise ValueError('boom in rule x')"), env_for(server))
    assert raises.returncode == 1
    assert "Traceback" in raises.stderr and "ValueError: boom in rule x" in raises.stderr


HOOKED = """
def hook(kind, err, tb):
    print(f"hooked {kind.__name__}: {err}", file=sys.stderr)
    sys.__excepthook__(kind, err, tb)
sys.excepthook = hook  # as tacgen_lib.io.log.for_rule writes a failure into the rule's log
raise ValueError("boom in rule x")
"""


def test_an_unhandled_exception_goes_through_the_scripts_excepthook_as_in_a_fresh_one(
    server, tmp_path
):
    served = run_job(job_script(tmp_path, HOOKED), env_for(server))
    fresh = run_job(job_script(tmp_path, HOOKED), env_for(None))
    for proc in (served, fresh):
        assert proc.returncode == 1
        assert "hooked ValueError: boom in rule x" in proc.stderr
        assert "Traceback" in proc.stderr


def test_usage_is_written_beside_the_benchmark_and_read_with_it(server, tmp_path):
    usage = tmp_path / (BENCH + ".usage.json")
    burn = "import numpy as np\nx = np.ones((400, 400))\nfor _ in range(60): x = x @ x * 1e-3\n"
    assert run_job(job_script(tmp_path, burn), env_for(server)).returncode == 0
    got = json.loads(usage.read_text())
    assert got["exitcode"] == 0 and got["cpu_s"] > 0 and got["max_rss_mb"] > 50
    assert not list(usage.parent.glob("*.tmp"))
    bench = tmp_path / BENCH
    bench.write_text("s\th:m:s\tmax_rss\tcpu_time\n1.5\t0:00:01\t30.0\t0.05\n")
    b = read_benchmark(bench)
    assert b.cpu == pytest.approx(got["cpu_s"] + 0.05)
    assert b.max_rss_mb == pytest.approx(max(got["max_rss_mb"], 30.0))
    # a failed job leaves none; a job in a fresh interpreter removes a stale one
    assert run_job(job_script(tmp_path, "sys.exit(2)"), env_for(server)).returncode == 2
    assert not usage.exists()
    assert run_job(job_script(tmp_path, burn), env_for(server)).returncode == 0
    assert usage.exists()
    assert run_job(job_script(tmp_path, "pass"), env_for(None)).returncode == 0
    assert not usage.exists()
    assert read_benchmark(bench).cpu == pytest.approx(0.05)


def test_unreadable_usage_file_is_named(tmp_path):
    bench = tmp_path / "r.tsv"
    bench.write_text("s\tcpu_time\n1.0\t0.5\n")
    preload.usage_path(bench).write_text("{not json")
    with pytest.raises(ValueError, match=r"r\.tsv\.usage\.json"):
        read_benchmark(bench)


def test_without_a_server_the_job_runs_in_its_own_interpreter(server, tmp_path):
    script = job_script(tmp_path, "print(preloaded)")
    nobody = run_job(script, env_for(f"tacgen-nobody-{uuid.uuid4().hex}"))
    assert (nobody.returncode, nobody.stdout.strip()) == (0, "False")
    off = run_job(script, env_for(server, **{preload.SWITCH_ENV: "0"}))
    assert (off.returncode, off.stdout.strip()) == (0, "False")
    on = run_job(script, env_for(server))
    assert (on.returncode, on.stdout.strip()) == (0, "True")


def _start(script: Path, env: dict[str, str], sigint=signal.SIG_DFL) -> subprocess.Popen:
    """The job's process, with SIGINT as given (pytest-xdist's workers ignore it, and a child
    inherits an ignored signal)."""
    return subprocess.Popen(
        [sys.executable, str(script)],
        cwd=script.parents[2],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, sigint),
    )


def test_signals_to_the_job_process_reach_the_job(server, tmp_path):
    body = f"""
    import signal, time, pathlib
    def stop(signum, frame):
        pathlib.Path({str(tmp_path / "got")!r}).write_text(str(signum))
        sys.exit(5)
    signal.signal(signal.SIGTERM, stop)
    pathlib.Path({str(tmp_path / "ready")!r}).write_text("")
    time.sleep(120)
    """
    proc = _start(job_script(tmp_path, body), env_for(server))
    assert _wait_until((tmp_path / "ready").exists, 60), proc.communicate(timeout=5)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 5
    assert (tmp_path / "got").read_text() == str(int(signal.SIGTERM))


def test_ctrl_c_interrupts_the_job_not_the_server(server, tmp_path):
    """SIGINT (a terminal's Ctrl-C reaches the whole process group) ends the job as it ends a
    fresh interpreter: KeyboardInterrupt, traceback, exit by SIGINT. The server ignores it and
    serves the next job."""
    ready = tmp_path / "ready"
    body = f"""
    import time, pathlib
    pathlib.Path({str(ready)!r}).write_text("")
    time.sleep(120)
    """
    script = job_script(tmp_path, body)
    results = []
    for name in (None, server):
        ready.unlink(missing_ok=True)
        proc = _start(script, env_for(name))
        assert _wait_until(ready.exists, 60), proc.communicate(timeout=5)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        results.append((proc.returncode, "KeyboardInterrupt" in err))
    assert results[0] == results[1] == (-signal.SIGINT, True)
    # a job process that ignores SIGINT (inherited) ignores it in the copy too, as fresh
    results = []
    for name in (None, server):
        ready.unlink(missing_ok=True)
        proc = _start(script, env_for(name), sigint=signal.SIG_IGN)
        assert _wait_until(ready.exists, 60), proc.communicate(timeout=5)
        proc.send_signal(signal.SIGINT)
        time.sleep(1.0)
        running = proc.poll() is None
        proc.terminate()
        results.append((running, proc.wait(timeout=60)))
    assert results[0] == results[1] == (True, -signal.SIGTERM)
    # the server itself: its forked supervisors and job copies carry its command line too, and
    # the one of the job just terminated may still be exiting (it would not be "alive" below)
    named = {
        int(p.name)
        for p in Path("/proc").iterdir()
        if p.name.isdigit() and server.encode() in _cmdline(int(p.name))
    }
    servers = []
    for pid in named:
        with contextlib.suppress(OSError, IndexError, ValueError):  # gone meanwhile: not it
            if _ppid(pid) not in named:
                servers.append(pid)
    for pid in servers:
        os.kill(pid, signal.SIGINT)
    time.sleep(0.5)
    assert servers and all(_alive(pid) for pid in servers)
    again = run_job(job_script(tmp_path, "print(preloaded)"), env_for(server))
    assert (again.returncode, again.stdout.strip()) == (0, "True")


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def _sleeping_job(server, tmp_path):
    """A job that sleeps in the server: (its process, the pid of its copy)."""
    pidfile = tmp_path / "pid"
    # written whole, then renamed into place: the test reads it as soon as it exists
    body = f"""
    import os, time, pathlib
    part = pathlib.Path({str(pidfile)!r} + ".part")
    part.write_text(str(os.getpid()))
    part.rename({str(pidfile)!r})
    time.sleep(120)
    """
    proc = _start(job_script(tmp_path, body), env_for(server))
    assert _wait_until(pidfile.exists, 60), proc.communicate(timeout=5)
    return proc, int(pidfile.read_text())


def test_a_killed_job_process_takes_its_copy_with_it(server, tmp_path):
    proc, copy = _sleeping_job(server, tmp_path)
    assert copy != proc.pid and _alive(copy)
    proc.kill()
    proc.wait(timeout=30)
    assert _wait_until(lambda: not _alive(copy), 30), "the job's copy outlived its process"


def test_a_job_killed_by_a_signal_exits_by_that_signal(server, tmp_path):
    got = run_job(
        job_script(tmp_path, "import os, signal\nos.kill(os.getpid(), signal.SIGUSR1)\n"),
        env_for(server),
    )
    assert got.returncode == -signal.SIGUSR1


def test_the_server_exits_when_its_snakemake_is_gone(tmp_path):
    """start_preloaded_interpreter as the Snakefile's onstart calls it, in a parent that then
    dies by SIGKILL (no onerror runs): the server notices and exits."""
    parent = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from tacgen_lib.runtime import preload_server\n"
            "p = preload_server.start_preloaded_interpreter(); print(p.pid, flush=True); time.sleep(600)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    server_pid = int(parent.stdout.readline())
    assert _alive(server_pid)
    parent.kill()
    parent.wait(timeout=30)
    assert _wait_until(lambda: not _alive(server_pid), 120), "the server outlived Snakemake"


def test_no_server_for_a_cluster_a_few_jobs_or_switched_off(monkeypatch):
    """No server, and no inherited server name (an enclosing run's) left for the jobs."""
    for kwargs in ({"jobs": preload_server.MIN_JOBS - 1}, {"jobs": 1000, "local": False}):
        monkeypatch.setenv(preload.SOCKET_ENV, "tacgen-an-enclosing-run")
        assert preload_server.start_preloaded_interpreter(**kwargs) is None
        assert preload.SOCKET_ENV not in os.environ
    monkeypatch.setenv(preload.SWITCH_ENV, "0")
    monkeypatch.setenv(preload.SOCKET_ENV, "tacgen-an-enclosing-run")
    assert preload_server.start_preloaded_interpreter(1000) is None
    assert preload.SOCKET_ENV not in os.environ


@pytest.mark.parametrize(
    ("log", "bench"),
    [
        ("results/logs/make_splits.log", "results/benchmarks/make_splits.tsv"),
        (
            "results/logs/probe/hardness/protocol~raw/seed~0.log",
            "results/benchmarks/probe/hardness/protocol~raw/seed~0.tsv",
        ),
        (
            "results/cost/patch/s0/logs/extract_features/sim/vision.log",
            "results/cost/patch/s0/benchmarks/extract_features/sim/vision.tsv",
        ),
        ("/abs/work/results/logs/x/a.b.log", "/abs/work/results/benchmarks/x/a.b.tsv"),
    ],
)
def test_benchmark_of_log(log, bench):
    assert preload.benchmark_of_log(log) == Path(bench)
    assert preload.usage_path(bench) == Path(bench + ".usage.json")


@pytest.mark.parametrize("log", ["results/benchmarks/x.tsv", "results/logs/x.txt", "x.log"])
def test_benchmark_of_a_path_that_is_no_log_is_refused(log):
    with pytest.raises(ValueError, match="results/logs"):
        preload.benchmark_of_log(log)


def test_every_workflow_script_offers_itself_to_the_server_first():
    """Each script's first statements (after its docstring) are the hook: before any import
    that the server would have saved."""
    for path in sorted((ROOT / "workflow/scripts").glob("*.py")):
        body = ast.parse(path.read_text()).body
        first, second = body[1], body[2]
        assert isinstance(first, ast.ImportFrom), path.name
        assert first.module == "tacgen_lib.runtime.preload", path.name
        assert [a.name for a in first.names] == ["run_in_preloaded_interpreter"], path.name
        assert ast.unparse(second) == "run_in_preloaded_interpreter(snakemake)", path.name


WHY = """
from tacgen_lib.runtime.preload import fresh_reason
print(preloaded, sys.prefix, fresh_reason(), sep="\\n")
"""


@pytest.mark.parametrize(
    ("variable", "value"),
    [
        ("PYTHONHASHSEED", "123"),  # a fresh interpreter's string hashes depend on it
        ("LD_LIBRARY_PATH", "/elsewhere"),  # which shared libraries an import loads
        ("LD_PRELOAD", ""),
        ("PYTHONPATH", "/elsewhere"),
    ],
)
def test_a_job_with_other_import_time_variables_runs_fresh_and_says_why(
    server, tmp_path, variable, value
):
    """PYTHON* and LD_* variables are read when an interpreter starts and imports: a job whose
    values differ from the server's runs fresh, and the reason names the variable."""
    assert variable not in os.environ or os.environ[variable] != value
    got = run_job(job_script(tmp_path, WHY), env_for(server, **{variable: value}))
    assert got.returncode == 0, got.stderr
    preloaded, _prefix, why = got.stdout.strip().split("\n")
    assert preloaded == "False"
    assert why.startswith("another environment") and variable in why, why
    # the thread counts differ per job: they are applied to the copy, not declined
    served = run_job(job_script(tmp_path, WHY), env_for(server, threads=2))
    assert served.stdout.split("\n")[0] == "True", served.stderr


def _tiny_venv(where: Path) -> Path:
    """A venv of this test's base interpreter (no packages of its own) that sees this
    project's packages through a .pth file: a stand-in for a rule's conda environment, which
    has its own prefix and interpreter."""
    import venv

    venv.EnvBuilder(with_pip=False, symlinks=True).create(where)
    python = where / "bin" / "python"
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    ours = [p for p in sys.path if p.endswith("site-packages") and p.startswith(sys.prefix)]
    Path(site, "tacgen_test.pth").write_text(f"import site; site.addsitedir({ours[0]!r})\n")
    return python


def test_a_job_in_another_environment_runs_in_it_not_in_the_server(server, tmp_path):
    """What `--sdm conda` does for a rule with `conda:`: Snakemake starts the script with the
    environment's `python`. The server (this project's .venv) declines it, the script runs in
    the environment's own interpreter, and the reason names the prefix."""
    python = _tiny_venv(tmp_path / "env")
    script = job_script(tmp_path, WHY)
    got = subprocess.run(
        [str(python), str(script)],
        cwd=script.parents[2],
        env=env_for(server),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert got.returncode == 0, got.stderr
    preloaded, prefix, why = got.stdout.strip().split("\n")
    assert preloaded == "False"
    assert Path(prefix) == tmp_path / "env"
    assert why.startswith("another interpreter") and "prefix" in why, why
    # the same script with the server's interpreter: served
    same = run_job(script, env_for(server))
    assert same.stdout.split("\n")[:2] == ["True", sys.prefix], same.stderr


def test_the_rule_log_says_why_a_job_ran_fresh(server, tmp_path):
    body = """
    from tacgen_lib.io import log
    log.for_rule(snakemake).info("work")
    """
    got = run_job(job_script(tmp_path, body), env_for(server, PYTHONHASHSEED="7"))
    assert got.returncode == 0, got.stderr
    text = (tmp_path / LOG).read_text()
    assert "runs in a fresh interpreter, not the preloaded one: another environment" in text
    assert "PYTHONHASHSEED" in text and "work" in text
    served = run_job(job_script(tmp_path, body), env_for(server))
    assert served.returncode == 0, served.stderr
    assert "fresh interpreter" not in (tmp_path / LOG).read_text()


def _ppid(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1].split()[1])


def _children(pid: int) -> list[int]:
    """Live (not zombie) processes whose parent is `pid`."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if _ppid(int(entry.name)) == pid and _alive(int(entry.name)):
                    out.append(int(entry.name))
            except (OSError, IndexError, ValueError):
                continue
    return out


def test_a_killed_supervisor_takes_the_job_with_it(server, tmp_path):
    """The copy's parent (its supervisor, which holds the job's connection) killed as the OOM
    killer would: the copy dies by its parent-death signal, the job's process fails."""
    proc, copy = _sleeping_job(server, tmp_path)
    supervisor = _ppid(copy)
    assert supervisor not in (proc.pid, os.getpid())
    os.kill(supervisor, signal.SIGKILL)
    assert _wait_until(lambda: not _alive(copy), 10), "the copy outlived its supervisor"
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 1 and "lost the job's process" in err


def _gated_server(tmp_path: Path, name: str) -> tuple[subprocess.Popen, Path, Path]:
    """A server whose second import (`gate`) returns only once the file `open` exists (its
    first, numpy, is done): a job that connects meanwhile waits in the socket's queue. Returns
    the server, the file `gate` touches when it starts, and `open`."""
    lib = tmp_path / "lib"
    lib.mkdir()
    started, release = tmp_path / "importing", tmp_path / "open"
    (lib / "gate.py").write_text(
        f"import os, pathlib, time\npathlib.Path({str(started)!r}).touch()\n"
        f"while not os.path.exists({str(release)!r}):\n    time.sleep(0.02)\n"
    )
    code = (
        f"import sys; sys.path.insert(0, {str(lib)!r})\n"
        "from tacgen_lib.runtime import preload_server\n"
        "preload_server.PRELOADED_MODULES = ('numpy', 'gate')\n"
        f"preload_server.serve({name!r}, {os.getpid()})"
    )
    return subprocess.Popen([sys.executable, "-P", "-c", code]), started, release


def test_a_job_process_that_dies_while_queued_leaves_no_copy(tmp_path):
    """The job's process is SIGKILLed while it waits for a busy server: when the server comes
    to it, the handshake fails before the fork (no "go"), and no copy ever runs."""
    name = f"tacgen-test-{os.getpid()}-{uuid.uuid4().hex}"
    server, started, release = _gated_server(tmp_path, name)
    ran = tmp_path / "ran"
    try:
        assert _wait_until(started.exists, 60), "the server did not reach its gated import"
        body = f"import pathlib\npathlib.Path({str(ran)!r}).write_text('ran')\n"
        proc = _start(job_script(tmp_path, body), env_for(name))
        assert _wait_until(lambda: _queued_on(name), 60), "the job never reached the server"
        time.sleep(0.3)  # its request is in the socket's buffer
        proc.kill()
        proc.wait(timeout=30)
        release.touch()
        # the server accepts the dead job's connection, forks its supervisor, which ends
        time.sleep(3)
        assert not ran.exists(), "a copy ran the job of a dead process"
        assert _wait_until(lambda: not _children(server.pid), 30), _children(server.pid)
        assert server.poll() is None
    finally:
        release.touch()
        server.terminate()
        server.wait(timeout=30)


def test_a_stalled_server_makes_the_job_run_fresh_and_the_log_says_so(tmp_path):
    """A server that takes the connection but never answers (here: a socket that listens and is
    never accepted): the job waits TACGEN_PRELOAD_TIMEOUT_S, runs in its own interpreter, and
    its rule's log says why."""
    name = f"tacgen-test-{os.getpid()}-{uuid.uuid4().hex}"
    body = """
    from tacgen_lib.io import log
    log.for_rule(snakemake).info("work")
    print(preloaded)
    """
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as stalled:
        stalled.bind("\0" + name)
        stalled.listen(8)
        t0 = time.monotonic()
        proc = _start(job_script(tmp_path, body), env_for(name, **{preload.TIMEOUT_ENV: "1"}))
        code = proc.wait(timeout=60)
        waited = time.monotonic() - t0
    # (the job's streams sat in the unread request until the socket closed: read them now)
    out, err = proc.communicate(timeout=30)
    assert (code, out.strip()) == (0, "False"), err
    assert 1.0 <= waited < 60
    text = (tmp_path / LOG).read_text()
    assert "the preloaded interpreter did not answer within 1 s" in text and "work" in text


def test_a_job_that_timed_out_on_a_busy_server_runs_once(tmp_path):
    """The job gives up on a server still importing and runs fresh; when the server comes to
    its connection, the job's process is gone, so the server forks no second copy."""
    name = f"tacgen-test-{os.getpid()}-{uuid.uuid4().hex}"
    server, started, release = _gated_server(tmp_path, name)
    runs = tmp_path / "runs"
    try:
        assert _wait_until(started.exists, 60), "the server did not reach its gated import"
        body = f"""
        with open({str(runs)!r}, "a") as f:
            f.write(f"{{preloaded}}\\n")
        """
        proc = _start(job_script(tmp_path, body), env_for(name, **{preload.TIMEOUT_ENV: "1"}))
        assert proc.wait(timeout=60) == 0
        release.touch()
        # (the job's streams sat in its queued request until the server took it)
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        time.sleep(3)
        assert runs.read_text() == "False\n"
        assert _wait_until(lambda: not _children(server.pid), 30), _children(server.pid)
    finally:
        release.touch()
        server.terminate()
        server.wait(timeout=30)


def test_a_stalled_client_holds_up_no_other_job(server, tmp_path):
    """A connection that sends nothing (a job process stopped mid-handshake): the server's loop
    does not read it (its supervisor does, with a timeout), so the next job is served at once."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as stuck:
        stuck.connect("\0" + server)
        t0 = time.monotonic()
        got = run_job(job_script(tmp_path, "print(preloaded)"), env_for(server), timeout=30)
        assert (got.returncode, got.stdout.strip()) == (0, "True"), got.stderr
        assert time.monotonic() - t0 < 30


RANDOM = """
import random, numpy as np, torch
print(random.random(), np.random.random(), torch.rand(1).item())
"""


def test_each_copy_starts_with_a_fresh_interpreters_random_state(server, tmp_path):
    """Python's random, numpy's legacy global RandomState and torch's default generator are
    seeded from the OS in a fresh interpreter: two copies of one server draw different numbers,
    as two fresh interpreters do (inherited unchanged, they drew the same)."""
    script = job_script(tmp_path, RANDOM)
    served = [run_job(script, env_for(server)) for _ in range(2)]
    fresh = run_job(script, env_for(None))
    for got in (*served, fresh):
        assert got.returncode == 0, got.stderr
    (r1, n1, t1), (r2, n2, t2) = (g.stdout.split() for g in served)
    assert r1 != r2 and n1 != n2 and t1 != t2
