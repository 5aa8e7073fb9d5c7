"""Fault injection: a crash, a full disk or a bad input never costs a result or
gives a wrong one.

Every workflow fault runs on config/test.yaml against one clean run (`reference_run`, shared
with test_workflow.py): recovery must end with every hashed edge (the `.sha256.json`
sidecars) equal to the clean run's.

- SIGKILL of the whole run (scheduler and jobs: its process group) while a job of each stage
  in `KILL_STAGES` is running. The stages share one run: it is started cold, killed while a
  job of the first stage the scheduler reaches runs, resumed with `tools/resume.py` (what
  `make resume` runs), killed again while a job of the next stage not yet killed runs, and so
  on; the last resume runs to the end. So the whole table costs about one cold run, not one
  per stage; that run is the session's
  (conftest.resumed_run, faults_run.kill_series), and test_workflow.py's determinism test
  compares its edges with the reference run's.
- SIGKILL of one job's process; a full disk under results/ (a tmpfs the test mounts); corrupt
  data inside well-hashed edges; two runs in one directory (the first holding a job that
  stays running until the test releases it, so the refusal never depends on timing).
- Hostile inputs: dataset CSV rows and symlinks leaving the dataset root, a crafted pickle
  checkpoint, fuzzed configs.
- 5,000 tactile + RGB frames rendered in one process without RSS growth.

Run with `-s` to see the figures (recovery seconds, RSS growth) the README's Reliability
table quotes.
"""

from __future__ import annotations

import copy
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from faults_run import (
    CONFIG,
    KILL_STAGES,
    RESUME,
    START_TIMEOUT,
    assert_no_half_written_edge,
    launch,
    resume,
    wait_for_job,
)
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from snakemake_run import ROOT, SNAKEMAKE, copy_run, copy_tree, edge_hashes, planned_rules, smk

from tacgen_lib.io import edges, hashed

pytestmark = pytest.mark.workflow

# `smk` ends its command with `--configfile config/test.yaml`: an option must come between
# that and a target, or the target is read as one more config file
TARGETS = ("--cores", "2")


def _report(what: str, **figures) -> None:
    print(f"\nRELIABILITY {what}: " + json.dumps(figures), flush=True)


# --------------------------------------------------------------------- kill -9 of the whole run


@pytest.mark.parametrize("stage", list(KILL_STAGES))
def test_sigkill_of_the_whole_run_during_each_stage(resumed_run, stage):
    """The session's kill series (conftest.resumed_run, faults_run.kill_series) killed the
    whole run while a job of `stage` ran: what a user finds then."""
    seen = resumed_run["kills"][stage]
    rule = seen["rule"]
    assert seen["pids"], f"no {rule} job was running"
    if seen["finished_early_exit"] is not None:  # the stage was forced after a finished run
        assert seen["finished_early_exit"] == 0, seen["log_tail"]
    # a stale lock and the killed job's incomplete marker ...
    assert seen["lock"], "the killed run left no lock"
    assert seen["incomplete"], "no incomplete marker"
    # ... and never a half-written edge
    assert seen["edge_error"] is None, seen["edge_error"]
    if "plain_rerun" in seen:  # after the first kill: a plain rerun is refused, for the stale
        # lock or, where Snakemake checks them first, for the killed jobs' incomplete outputs
        plain = seen["plain_rerun"]
        out = plain.stdout + plain.stderr
        assert plain.returncode != 0
        assert "LockException" in out or "locked" in out or "Incomplete files" in out, out
    _report(
        f"kill -9 during {stage} ({rule})",
        edges_verified=seen["edges_verified"],
        job_pids=seen["pids"],
        seconds=seen["seconds"],
    )


def test_one_resume_after_the_kills_gives_a_clean_runs_edges(resumed_run, reference_run):
    work, final = resumed_run["work"], resumed_run["final"]
    assert final["exit"] == 0, final["log"][-6000:]
    assert "resume: lock cleared" in final["log"]
    got, want = edge_hashes(work), edge_hashes(reference_run)
    assert want and got == want, {k: (got.get(k), v) for k, v in want.items() if got.get(k) != v}
    assert not resume.stale_temporaries(work)
    assert planned_rules(work) == {}
    _report(
        "resume after kills",
        kills=[(s, k["rule"], k["seconds"]) for s, k in resumed_run["kills"].items()],
        edges_equal=f"{len(got)}/{len(want)}",
        last_resume_seconds=final["seconds"],
    )


# --------------------------------------------------------------------- one job killed


def test_sigkill_of_one_job_is_reported_and_only_it_and_its_downstream_rerun(
    reference_run, tmp_path
):
    rule = "pretrained_vs_random"
    work = copy_run(reference_run, tmp_path / "job")
    planned = planned_rules(work, "--forcerun", rule)
    assert planned.get(rule) == 1 and "probe" not in planned, planned
    log = tmp_path / "job.log"
    proc = launch(work, [*SNAKEMAKE, "--cores", "2", *CONFIG, "--forcerun", rule], log)
    pids = wait_for_job(proc, work, rule)
    assert pids, log.read_text()[-4000:]
    for pid in pids:
        os.kill(pid, signal.SIGKILL)  # the job only; Snakemake lives on
    assert proc.wait(timeout=300) != 0
    out = log.read_text()
    assert f"Error in rule {rule}" in out, out[-4000:]
    # the scheduler cleaned up (no lock, no incomplete marker): the plan is exactly the killed
    # job and what reads its outputs, and nothing else
    assert planned_rules(work) == planned
    t0 = time.monotonic()
    smk(work)
    seconds = time.monotonic() - t0
    got, want = edge_hashes(work), edge_hashes(reference_run)
    assert got == want
    _report(
        f"kill -9 of one {rule} job",
        rerun=planned,
        edges_equal=f"{len(got)}/{len(want)}",
        rerun_seconds=round(seconds, 1),
    )


# --------------------------------------------------------------------- two runs, one directory


#: a rule the two-runs test appends to its copy's Snakefile: its job says it has started, then
#: stays running, its output not yet written, until the test creates the release file
HOLD_RULE = """

rule hold_for_test:
    output:
        "results/test_hold/released.txt",
    shell:
        "touch {started}; while [ ! -e {release} ]; do sleep 0.05; done; touch {{output:q}}"
"""


def test_second_run_in_the_same_directory_is_refused_and_the_first_completes(
    reference_run, tmp_path
):
    """The first run holds a job that stays running, its output not yet written, until the
    test releases it; so every attempt of a second run meets the same state, whatever the
    timing. Snakemake checks incomplete markers only on outputs that exist (none here), then
    locks the files its jobs read and write: a live run holding a lock on an output the second
    run must make refuses it with LockException ("Directory cannot be locked"), with or without
    --rerun-incomplete; `make resume` refuses it too, naming the live run's pid."""
    work = copy_run(reference_run, tmp_path / "two")
    started, release = tmp_path / "hold.started", tmp_path / "hold.release"
    with (work / "Snakefile").open("a") as fh:
        fh.write(
            HOLD_RULE.format(started=shlex.quote(str(started)), release=shlex.quote(str(release)))
        )
    target = "results/test_hold/released.txt"
    log = tmp_path / "first.log"
    first = launch(work, [*SNAKEMAKE, "--cores", "2", *CONFIG, "--", target], log)
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while not started.exists():
            assert first.poll() is None, log.read_text()[-4000:]
            assert time.monotonic() < deadline, "the held job never started"
            time.sleep(0.05)
        assert not (work / target).exists()  # the held job's output is not written yet
        for extra in ((), ("--rerun-incomplete",)):
            second = smk(work, *extra, "--", target, check=False)
            out = second.stdout + second.stderr
            assert second.returncode != 0, out[-3000:]
            assert "LockException" in out and "Directory cannot be locked" in out, out[-3000:]
            assert "IncompleteFilesException" not in out
        refused = subprocess.run(
            [*RESUME, *CONFIG, "--", target], cwd=work, capture_output=True, text=True, timeout=60
        )
        assert refused.returncode == 3, refused.stderr
        assert f"pid {first.pid}" in refused.stderr and "refused" in refused.stderr
        assert first.poll() is None  # no attempt touched the first run
    finally:
        release.touch()
    rc = first.wait(timeout=120)
    assert rc == 0, log.read_text()[-4000:]
    assert (work / target).exists()
    locks = work / ".snakemake/locks"
    assert not locks.exists() or not list(locks.iterdir())  # the first run released its lock
    assert edge_hashes(work) == edge_hashes(reference_run)


# --------------------------------------------------------------------- full disk


def test_full_disk_names_the_file_leaves_no_half_edge_and_recovers(reference_run, tmp_path):
    if os.geteuid() != 0 or not shutil.which("mount"):
        pytest.skip("needs root and mount(8) to put results/ on a small tmpfs")
    work = copy_tree(tmp_path / "disk")
    shutil.copytree(reference_run / ".snakemake", work / ".snakemake")
    results = work / "results"
    results.mkdir()
    size_mb = 128  # the test run's results (about 80 MB) and room to fill
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size_mb}m", "tacgen-full-disk", str(results)],
        capture_output=True,
        text=True,
    )
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs for results/: {mounted.stderr.strip()}")
    try:
        shutil.copytree(reference_run / "results", results, dirs_exist_ok=True)
        target = "results/preprocess/sim_controlled/clip128.parquet"
        size = (reference_run / target).stat().st_size
        (work / target).unlink()  # the job to redo (background subtraction of one corpus)
        # fill the disk, leaving a third of what the edge needs
        stat = os.statvfs(results)
        filler = results / "filler.bin"
        filler.write_bytes(b"\0" * (stat.f_bavail * stat.f_frsize - size // 3))
        full = smk(work, *TARGETS, target, check=False)
        out = full.stdout + full.stderr
        assert full.returncode != 0
        assert f"{target}: cannot write" in out and "No space left on device" in out, out[-4000:]
        assert not (work / target).exists()
        assert assert_no_half_written_edge(work) > 10
        assert not [p for p in results.rglob("*.tmp")]
        filler.unlink()  # space freed
        t0 = time.monotonic()
        smk(work, *TARGETS, target)
        seconds = time.monotonic() - t0
        got, want = edge_hashes(work), edge_hashes(reference_run)
        assert got == want
        _report(
            "full disk",
            failed_writing=target,
            edges_equal=f"{len(got)}/{len(want)}",
            rerun_seconds=round(seconds, 1),
        )
    finally:
        subprocess.run(["umount", str(results)], check=False)


# --------------------------------------------------------------------- corrupt data, good hash


def _rewrite(path: Path, edit) -> str:
    """Rewrite a corpus edge with `edit(frame)` applied and a fresh, valid sidecar: the hash
    is right, the content is bad. Returns the sample_id that was corrupted."""
    edge = edges.read(path)
    frame = edge.frame.copy()
    sid = edit(frame)
    edges.write(path, frame, edge.vectors, key=edge.key, producer="test_faults")
    return sid


def _undecodable_tactile(frame: pd.DataFrame) -> str:
    frame.at[3, "tactile"] = b"\x89PNG\r\n\x1a\n" + b"\0" * 64
    return frame.at[3, "sample_id"]


def _wrong_size_rgb(frame: pd.DataFrame) -> str:
    from tacgen_lib.io.images import encode_png

    frame.at[5, "rgb"] = encode_png(np.zeros((17, 23, 3), np.uint8))
    return frame.at[5, "sample_id"]


def _nan_label(frame: pd.DataFrame) -> str:
    frame.at[7, "mass"] = float("nan")
    return frame.at[7, "sample_id"]


CORRUPTIONS = {
    # name: (edge, edit, target whose rule consumes the edge, column named)
    "undecodable_png": (
        "results/corpus/sim_paired/samples.parquet",
        _undecodable_tactile,
        "results/preprocess/sim_paired/clip128.parquet",
        "tactile",
    ),
    "wrong_size_image": (
        "results/corpus/sim_controlled/samples.parquet",
        _wrong_size_rgb,
        "results/features/sim_controlled/vision.parquet",
        "rgb",
    ),
    "nan_label": (
        "results/corpus/sim_controlled/samples.parquet",
        _nan_label,
        "results/corpus/manifest.parquet",
        "mass",
    ),
}


@pytest.mark.parametrize("case", list(CORRUPTIONS))
def test_corrupt_data_in_a_well_hashed_edge_is_named(reference_run, tmp_path, case):
    edge, edit, target, column = CORRUPTIONS[case]
    work = copy_run(reference_run, tmp_path / case)
    sid = _rewrite(work / edge, edit)
    # the consumer alone reads it: the rewritten edge and its sidecar keep the reference run's
    # times (so no upstream job reruns first), and the target is forced
    for path in (work / edge, (work / edge).with_name(Path(edge).name + hashed.SIDECAR_SUFFIX)):
        before = (reference_run / path.relative_to(work)).stat()
        os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
    proc = smk(work, *TARGETS, "--force", target, check=False)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0
    ran = re.findall(r"(?m)^(?:local)?rule (\w+):", out)
    assert len(ran) == 1, ran  # the consumer's job, and only it
    message = next((line for line in out.splitlines() if sid in line and column in line), None)
    assert message is not None and edge in message, out[-5000:]
    print(f"\n{case}: {message.strip()[:300]}")


def test_empty_corpus_shard_is_named(reference_run, tmp_path):
    work = copy_run(reference_run, tmp_path / "shard")
    samples = edges.read(work / "results/corpus/sim_paired/samples.parquet")
    shard = "results/corpus/sim_paired/shards/0.parquet"
    edges.write(work / shard, samples.frame.iloc[:0], producer="test_faults")
    proc = smk(
        work,
        *TARGETS,
        "results/corpus/sim_paired/samples.parquet",
        "--forcerun",
        "merge_corpus",
        "--allowed-rules",
        "merge_corpus",
        check=False,
    )
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert f"{shard}: shard 0 has no rows" in out and "'sim_paired-000000'" in out, out[-4000:]


# --------------------------------------------------------------------- hostile inputs


def _hct(tmp_path: Path) -> tuple[Path, Path]:
    from fixtures_real import write_hct_fixture

    root = write_hct_fixture(tmp_path / "tvl", n_traj=1, per_traj=4)
    return root, next((root / "hct").glob("data*/train.csv"))


def _edit_first_row(csv_path: Path, column: int, value: str) -> None:
    rows = [line.split(",") for line in csv_path.read_text().splitlines()]
    rows[1][column] = value
    csv_path.write_text("\n".join(",".join(r) for r in rows) + "\n")


@pytest.mark.parametrize("how", ["absolute", "dotdot", "symlink"])
def test_dataset_paths_leaving_the_root_are_refused(tmp_path, how):
    from tacgen_lib.corpus.ingest import ingest_hct

    root, csv_path = _hct(tmp_path)
    secret = tmp_path / "outside" / "secret.jpg"
    secret.parent.mkdir()
    first_tactile = csv_path.parent / csv_path.read_text().splitlines()[1].split(",")[1]
    shutil.copy(first_tactile, secret)  # a readable image: only its place is wrong
    if how == "absolute":
        _edit_first_row(csv_path, 1, str(secret))
    elif how == "dotdot":
        _edit_first_row(csv_path, 1, os.path.relpath(secret, csv_path.parent))
    else:
        first_tactile.unlink()
        first_tactile.symlink_to(secret)
    with pytest.raises(ValueError, match=r"outside the dataset root") as err:
        ingest_hct(root)
    assert "sample_id 'hct-data1-00000'" in str(err.value) and "secret.jpg" in str(err.value)


def test_ssvtp_symlink_out_of_the_root_is_refused(tmp_path):
    from fixtures_real import write_ssvtp_fixture

    from tacgen_lib.corpus.ingest import ingest_ssvtp

    root = write_ssvtp_fixture(tmp_path / "tvl", n=4)
    outside = tmp_path / "elsewhere.txt"
    outside.write_text("hard, smooth")
    label = root / "ssvtp/text/labels_2.txt"
    label.unlink()
    label.symlink_to(outside)
    with pytest.raises(ValueError, match=r"sample_id 'ssvtp-000002': caption path .* outside"):
        ingest_ssvtp(root)


class _Payload:
    """Unpickling this calls open(marker, "w"): a stand-in for any code a pickle may run."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def test_crafted_pickle_checkpoint_is_refused_without_running_code(tmp_path):
    import torch

    from tacgen_lib.align.checkpoint import load_heads
    from tacgen_lib.features.vit_checkpoint import load_backbone

    marker = tmp_path / "side_effect"
    ckpt = tmp_path / "dinov2_vits14_pretrain.pth"
    torch.save({"cls_token": torch.zeros(1, 1, 8), "evil": _Payload(marker)}, ckpt)
    with pytest.raises(ValueError, match=r"not a tensor state dict; refused to unpickle"):
        load_backbone(ckpt)
    with pytest.raises(ValueError, match=r"not a readable heads file"):
        load_heads(ckpt, verify=False)
    assert not marker.exists(), "unpickling ran the payload"
    # control: the payload is live; an unsafe load would have run it
    torch.load(ckpt, weights_only=False)
    assert marker.exists()


# fuzzed configs: every value the schema constrains, replaced by a hostile one
_HOSTILE = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.lists(st.one_of(st.integers(-5, 5), st.text(max_size=3)), max_size=3),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def _leaf_paths(node, prefix=()) -> list[tuple]:
    if isinstance(node, dict):
        out = [prefix] if prefix else []
        for k, v in node.items():
            out += _leaf_paths(v, (*prefix, k))
        return out
    if isinstance(node, list):
        return [prefix] + [p for i, v in enumerate(node) for p in _leaf_paths(v, (*prefix, i))]
    return [prefix]


def _dotted(path: tuple) -> str:
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def _base_config() -> dict:
    """The test config as a user writes it, every key the schema defaults written out (the
    schema's defaults, the regime's corpora not yet joined): each is a key to fuzz."""
    from snakemake_run import merged_config

    from tacgen_lib.io.config import validate_schema

    cfg = merged_config()
    cfg["scenes_file"] = str(ROOT / cfg["scenes_file"])
    return validate_schema(cfg, ROOT / "config/config.schema.yaml")


_BASE = _base_config()
_PATHS = [p for p in _leaf_paths(_BASE) if p and p != ("scenes_file",)]


def _build_every_settings_object(cfg: dict) -> None:
    """What the scripts build from a validated config (the rules build tacgen_lib.plan)."""
    from tacgen_lib.align.settings import AlignSettings
    from tacgen_lib.corpus.sim.samples import CorpusSettings
    from tacgen_lib.features.settings import DinoSettings
    from tacgen_lib.probes.settings import ProbeSettings

    AlignSettings.from_config(cfg["align"])
    DinoSettings.from_config(cfg["features"]["pretrain"])
    for name, corpus in cfg["corpora"].items():
        if corpus["kind"] == "simulated":
            CorpusSettings.from_config({"name": name, **corpus})
    for spec in cfg["probes"]["families"].values():
        for seed in cfg["probes"]["seeds"]:
            ProbeSettings.from_config(cfg["probes"], spec["kind"], seed)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(where=st.sampled_from(_PATHS), value=_HOSTILE)
@example(where=("align", "lr"), value=float("inf"))  # found by this test once: kept as a case
@example(where=("corpora", "sim_transfer", "n"), value=1)  # 1 object of 6 contacts: found once
@example(
    where=("regime", "corpus", "scene"), value="0"
)  # named as corpora.<regime corpus>: found once
@example(where=("regime", "corpus"), value=None)  # found once: a TypeError, not the key
# found once: the regime off, and the error named features.pretrain.corpus's regime corpus only
@example(where=("regime", "rhos"), value=[])
def test_fuzzed_config_validates_or_names_the_key(where, value):
    from tacgen_lib.workflow_config import ConfigError, validate_config

    cfg = copy.deepcopy(_BASE)
    node = cfg
    for part in where[:-1]:
        node = node[part]
    node[where[-1]] = value
    try:
        validate_config(cfg, ROOT / "config/config.schema.yaml", source="fuzz.yaml")
    except ConfigError as err:
        # the message names the changed key, or the key above it (a list or mapping)
        named = [_dotted(where[:k]) for k in range(len(where), 0, -1)]
        assert any(name in str(err) for name in named), (where, value, str(err))
        return
    # valid: then no rule may fail on it while building its settings
    _build_every_settings_object(cfg)


# --------------------------------------------------------------------- long runs do not leak

LEAK_FRAMES, LEAK_WARMUP = 5000, 500
LEAK_BOUND_MB = 16.0  # over 4,500 frames: < 3.6 kB a frame (a peer simulator leaked 3 MB/frame)


def test_rendering_5000_tactile_and_rgb_frames_does_not_grow_rss():
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tests/leak_render.py"),
            str(ROOT / "config/scenes.yaml"),
            str(LEAK_FRAMES),
            str(LEAK_WARMUP),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    _report("render leak", **got, bound_mb=LEAK_BOUND_MB)
    assert got["png_bytes"] > LEAK_FRAMES * 1000  # the frames were really rendered and encoded
    assert got["growth_mb"] < LEAK_BOUND_MB, got


def test_resume_clears_the_lock_of_the_directory_snakemake_is_given(tmp_path):
    """With --directory among the arguments, the workflow directory is that one: its stale
    lock is cleared, the working directory's is not (`--version`: Snakemake starts, runs
    nothing)."""
    given, here = tmp_path / "given", tmp_path / "here"
    for d in (given, here):
        (d / ".snakemake/locks").mkdir(parents=True)
        (d / ".snakemake/locks/0.input.lock").write_text("results/x\n")
    proc = subprocess.run(
        [*RESUME, "--directory", str(given), "--version"],
        cwd=here,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "resume: lock cleared" in proc.stdout
    assert not (given / ".snakemake/locks").exists()
    assert (here / ".snakemake/locks/0.input.lock").exists()


def test_make_resume_runs_the_resume_tool():
    dry = subprocess.run(
        ["make", "-n", "-f", str(ROOT / "Makefile"), "resume", "ARGS=--configfile x.yaml"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert dry.returncode == 0, dry.stderr
    assert "tools/resume.py --cores 2 --configfile x.yaml" in dry.stdout
