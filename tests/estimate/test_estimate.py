"""Run-time estimate before running (tacgen_lib.estimate: .predict, .command, .schedule, .calibration, .units).

Scheduling on tiny hand-made DAGs, the non-negative least-squares fit recovering known per-unit
costs, clear errors naming the rule, and the shipped calibration over the real DAGs. How close
an estimate comes to a measured run is a timing, so it is a benchmark, not a test here:
benchmarks/bench_estimate.py.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from snakemake_run import hand_config

from tacgen_lib.estimate.calibration import (
    CALIBRATION_COLUMNS,
    Calibration,
    MissingCalibrationError,
    fit_costs,
    load_calibration,
    load_factors,
)
from tacgen_lib.estimate.command import format_estimate, write_table
from tacgen_lib.estimate.dag import DagJob
from tacgen_lib.estimate.predict import estimate_run, job_seconds, workflow_overhead
from tacgen_lib.estimate.schedule import Machine, Task, list_schedule, local_machine, slurm_machine
from tacgen_lib.estimate.units import UNITS, MissingUnitsError, job_units

# ---- scheduling -----------------------------------------------------------------------------


def chain(n: int, seconds: float = 10.0, start: int = 0) -> list[Task]:
    return [Task(start + i, seconds, 1, (start + i - 1,) if i else ()) for i in range(n)]


def test_serial_chain_takes_its_sum_whatever_the_cores():
    tasks = chain(4)
    for cores in (1, 2, 8):
        assert list_schedule(tasks, local_machine(cores)).makespan == pytest.approx(40.0)


def test_fan_out_spreads_over_the_cores():
    # one root, six 10-s children, one join: 1 + ceil(6 / cores) rounds + 1
    root = Task(0, 1.0)
    kids = [Task(i, 10.0, 1, (0,)) for i in range(1, 7)]
    join = Task(7, 1.0, 1, tuple(range(1, 7)))
    tasks = [root, *kids, join]
    assert list_schedule(tasks, local_machine(1)).makespan == pytest.approx(62.0)
    assert list_schedule(tasks, local_machine(2)).makespan == pytest.approx(32.0)
    assert list_schedule(tasks, local_machine(3)).makespan == pytest.approx(22.0)
    assert list_schedule(tasks, local_machine(6)).makespan == pytest.approx(12.0)


def test_two_thread_jobs_on_two_cores_run_one_at_a_time():
    tasks = [Task(0, 10.0, threads=2), Task(1, 10.0, threads=2)]
    assert list_schedule(tasks, local_machine(2)).makespan == pytest.approx(20.0)
    # threads above the machine's cores are capped (as --cores caps them): still runs
    assert list_schedule([Task(0, 5.0, threads=8)], local_machine(2)).makespan == 5.0
    # a 2-thread job and two 1-thread jobs: the pair shares the cores, then the big one
    mixed = [Task(0, 10.0, threads=2), Task(1, 10.0), Task(2, 10.0)]
    assert list_schedule(mixed, local_machine(2)).makespan == pytest.approx(20.0)


def test_long_chain_beats_sum_over_cores():
    # a 4-job chain and two independent jobs on 2 cores: sum / N says 30 s, the chain 40 s
    tasks = chain(4) + [Task(10, 10.0), Task(11, 10.0)]
    span = list_schedule(tasks, local_machine(2)).makespan
    assert sum(t.seconds for t in tasks) / 2 == 30.0
    assert span == pytest.approx(40.0)


def test_dependencies_are_honoured():
    tasks = [Task(0, 3.0), Task(1, 5.0), Task(2, 1.0, 1, (0, 1))]
    s = list_schedule(tasks, local_machine(4))
    assert s.start[2] >= max(s.end[0], s.end[1])
    assert s.makespan == pytest.approx(6.0)


def test_slurm_nodes_queue_overhead_and_local_rules():
    machine = slurm_machine(2, 2, queue_s=5.0, max_jobs=None, local_cores=1)
    # four 2-thread jobs: two nodes take two at a time, each waits 5 s in the queue
    tasks = [Task(i, 10.0, threads=2) for i in range(4)]
    assert list_schedule(tasks, machine).makespan == pytest.approx(30.0)
    # a localrules job after them runs on the host without queueing
    tasks.append(Task(4, 1.0, 1, (0, 1, 2, 3), local=True))
    assert list_schedule(tasks, machine).makespan == pytest.approx(31.0)
    # a job needs its threads on one node: 2 nodes x 2 cores cannot co-run two 3-thread jobs
    big = [Task(0, 10.0, threads=3), Task(1, 10.0, threads=3)]
    two_nodes = Machine(nodes=(2, 2))
    assert list_schedule(big, two_nodes).makespan == pytest.approx(10.0)  # capped at 2 each


def test_slurm_job_limit():
    tasks = [Task(i, 10.0) for i in range(4)]
    limited = slurm_machine(4, 4, queue_s=0.0, max_jobs=2)
    assert list_schedule(tasks, limited).makespan == pytest.approx(20.0)


def test_cycle_and_unknown_dependency_raise():
    with pytest.raises(ValueError, match="cycle"):
        list_schedule([Task(0, 1.0, 1, (1,)), Task(1, 1.0, 1, (0,))], local_machine(2))
    with pytest.raises(ValueError, match="unknown task 9"):
        list_schedule([Task(0, 1.0, 1, (9,))], local_machine(2))


# ---- fit ----------------------------------------------------------------------------------------


def points(rows) -> pd.DataFrame:
    return pd.DataFrame(
        [
            ("r", "-", c, c.split(":")[0], f"j{i}", 1, u, 0.0, w, w)
            for i, (c, u, w) in enumerate(rows)
        ],
        columns=CALIBRATION_COLUMNS,
    )


def test_fit_recovers_known_per_unit_costs():
    rng = np.random.default_rng(0)
    truth = {
        "simulate_corpus": (2.5, 0.04),
        "train_heads": (4.0, 0.002),
        "probe:ridge/raw": (1.5, 1e-4),
    }
    rows = []
    for cls, (a, b) in truth.items():
        for u in rng.uniform(100, 50_000, size=6):
            rows.append((cls, u, a + b * u))
    lines = fit_costs(points(rows))
    for cls, (a, b) in truth.items():
        assert lines[cls].identified
        assert lines[cls].overhead == pytest.approx(a, rel=1e-6)
        assert lines[cls].per_unit == pytest.approx(b, rel=1e-6)
        assert lines[cls].spread < 1e-9


def test_fit_is_non_negative_and_handles_a_single_units_value():
    # walls falling with units would need a negative per-unit cost: clamped at 0
    lines = fit_costs(points([("merge_corpus", 10, 5.0), ("merge_corpus", 1000, 4.0)]))
    assert lines["merge_corpus"].per_unit >= 0 and lines["merge_corpus"].overhead >= 0
    # one units value, or units too close: flat at the mean, flagged as not identified
    rows = [("a", 1, 3.0), ("a", 11, 13.0), ("c", 50, 12.0), ("d", 100, 10.0), ("d", 150, 14.0)]
    lines = fit_costs(points(rows))
    assert lines["a"].identified
    for cls, mean in (("c", 12.0), ("d", 12.0)):
        assert not lines[cls].identified
        assert lines[cls].per_unit == 0.0 and lines[cls].seconds(1e6) == pytest.approx(mean)


def test_runs_under_different_loads_fit_one_line():
    # the same jobs measured on idle cores (wall = 1.2 x CPU) and shared ones (wall = 7.2 x CPU)
    rows = []
    for run, factor in (("idle", 1.2), ("shared", 7.2)):
        for u in (100.0, 1000.0, 5000.0):
            cpu_s = 2.0 + 0.01 * u
            rows.append(
                (
                    run,
                    "-",
                    "simulate_corpus",
                    "simulate_corpus",
                    f"{run}{u}",
                    1,
                    u,
                    0.0,
                    factor * cpu_s,
                    cpu_s,
                )
            )
    pts = pd.DataFrame(rows, columns=CALIBRATION_COLUMNS)
    assert load_factors(pts) == pytest.approx({"idle": 1.0, "shared": 6.0})
    line = fit_costs(pts)["simulate_corpus"]  # idle seconds: 1.2 x CPU
    assert line.overhead == pytest.approx(2.4) and line.per_unit == pytest.approx(0.012)
    assert line.spread < 1e-9
    raw = fit_costs(pts, unshared=False)["simulate_corpus"]
    assert raw.spread > 0.5  # mixing the two loads unnormalised fits neither


def test_workflow_overhead_from_run_totals():
    runs = pd.DataFrame({"jobs": [80, 180], "wall": [100.0, 640.0], "makespan": [70.0, 590.0]})
    startup, per_job = workflow_overhead(runs)
    assert startup + 80 * per_job == pytest.approx(30.0)
    assert startup + 180 * per_job == pytest.approx(50.0)


# ---- errors name the rule ---------------------------------------------------------------------


def test_rule_without_unit_definition_is_named():
    with pytest.raises(MissingUnitsError, match="rule 'brand_new_rule' has no unit definition"):
        job_units("brand_new_rule", {}, {})


def test_rule_whose_config_cannot_be_counted_is_named():
    with pytest.raises(MissingUnitsError, match="rule 'merge_corpus'.*sim_x"):
        job_units("merge_corpus", {"corpora": {}}, {"corpus": "sim_x"})


def test_rule_without_calibration_is_named():
    cfg = hand_config({"c": {"n": 10}})
    jobs = [DagJob(0, "merge_corpus", {"corpus": "c"})]
    lines = fit_costs(points([("background_subtract", 1, 1.0), ("background_subtract", 2, 2.0)]))
    with pytest.raises(MissingCalibrationError, match="rule 'merge_corpus'"):
        job_seconds(jobs, cfg, lines)


def test_every_rule_of_the_workflow_has_a_unit_line():
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    rules = {
        m.group(1)
        for smk in [root / "Snakefile", *(root / "rules").glob("*.smk")]
        for m in re.finditer(r"^rule (\w+):", smk.read_text(), re.M)
    }
    missing = sorted(rules - set(UNITS) - {"all"})
    assert not missing, f"rules without a line in tacgen_lib/estimate/units.py UNITS: {missing}"


# ---- the estimate end to end on a hand DAG ------------------------------------------------------


def test_estimate_of_a_hand_dag_from_a_calibration(tmp_path):
    cfg = hand_config({"c": {"n": 100, "shards": 2, "presses": 3}})
    jobs = [
        DagJob(0, "simulate_corpus", {"corpus": "c", "shard": "0"}),
        DagJob(1, "simulate_corpus", {"corpus": "c", "shard": "1"}),
        DagJob(2, "merge_corpus", {"corpus": "c"}, deps=(0, 1)),
        DagJob(3, "all", {}, runs=False, deps=(2,)),
    ]
    pts = points(
        [("simulate_corpus", 50, 2.0 + 0.1 * 50), ("simulate_corpus", 150, 2.0 + 0.1 * 150)]
        + [("merge_corpus", 10, 1.0 + 0.01 * 10), ("merge_corpus", 1000, 1.0 + 0.01 * 1000)]
    )
    runs = pd.DataFrame(
        {
            "run": ["x"],
            "config": ["-"],
            "cpu": ["cpu"],
            "jobs": [3],
            "cores": [2],
            "wall": [10.0],
            "makespan": [10.0],
        }
    )
    est = estimate_run(jobs, cfg, Calibration(pts, runs, "hand"), local_machine(2))
    by_rule = est.per_rule.set_index("rule")
    # each shard 150 sample-presses: 2 + 15 = 17 s, side by side; merge 100 samples: 2 s
    assert by_rule.loc["simulate_corpus", "job_seconds"] == pytest.approx(34.0)
    assert est.makespan == pytest.approx(19.0)
    assert est.overhead == pytest.approx(0.0)
    one_core = estimate_run(jobs, cfg, Calibration(pts, runs, "hand"), local_machine(1))
    assert one_core.makespan == pytest.approx(36.0)
    # the table the report can show: per rule, and a total row saying machine and source
    write_table(est, tmp_path / "estimate.parquet")
    table = pd.read_parquet(tmp_path / "estimate.parquet").set_index("rule")
    assert table.loc["total", "end_s"] == pytest.approx(19.0)
    assert table.loc["simulate_corpus", "jobs"] == 2 and set(table["source"]) == {"hand"}
    assert "total predicted wall time: 19 s" in format_estimate(est)


def test_shipped_calibration_is_labelled_with_its_cpu():
    cal = load_calibration()
    assert cal.cpus and all("cores" in c and "vector" in c for c in cal.cpus)
    assert set(cal.points["run"]) >= {"test", "default"}
    assert "CPU" in cal.source


@pytest.mark.parametrize("configfile", ["config/test.yaml", "config/config.yaml"])
def test_shipped_calibration_estimates_the_real_dags(configfile):
    """Snakemake's own DAG of each config (no run): every job has units and a calibrated
    class; the schedule honours the DAG (a job never starts before what it waits for); every
    benchmarked job's benchmark file is its log file's by the workflow's convention."""
    from pathlib import Path

    from tacgen_lib.estimate.dag import dag_jobs

    root = Path(__file__).resolve().parents[2]
    jobs, config = dag_jobs([configfile], workdir=root)
    assert {j.rule for j in jobs} >= {"simulate_corpus", "train_heads", "probe"}
    est = estimate_run(jobs, config, load_calibration(), local_machine(2))
    per_rule = est.per_rule.set_index("rule")
    assert per_rule["jobs"].sum() == sum(j.runs for j in jobs)
    assert est.total > est.makespan >= per_rule["job_seconds"].sum() / 2
    assert per_rule.loc["make_splits", "start_s"] >= per_rule.loc["fuse_manifest", "end_s"]
    # the convention the preloaded interpreter writes a job's usage by: benchmark = log, moved
    from tacgen_lib.runtime.preload import benchmark_of_log

    wrong = {
        j.rule: (j.log, j.benchmark)
        for j in jobs
        if j.benchmark is not None
        and (j.log is None or benchmark_of_log(j.log) != Path(j.benchmark))
    }
    assert not wrong, wrong


# ---- cells in one-thread workers, the critical chain, a GPU class ------------------------------


def test_longest_first_makespan_of_cells_on_workers():
    from tacgen_lib.estimate.schedule import longest_first_makespan

    cells = [10.0, 7.0, 5.0, 3.0, 3.0, 2.0]
    assert longest_first_makespan(cells, 1) == pytest.approx(30.0)  # one worker: the sum
    # two workers, longest first: 10 | 7 5 -> 10+3+2=15 | 12+3=15
    assert longest_first_makespan(cells, 2) == pytest.approx(15.0)
    # as many workers as cells or more: the longest cell
    assert longest_first_makespan(cells, 6) == longest_first_makespan(cells, 64) == 10.0
    assert longest_first_makespan([], 4) == 0.0


def test_critical_chain_is_the_longest_dependent_path():
    from tacgen_lib.estimate.schedule import critical_chain

    # 0 -> 1 -> 3 (1 + 10 + 2) beats 0 -> 2 -> 3 (1 + 4 + 2); 4 stands alone (5 s)
    tasks = [
        Task(0, 1.0),
        Task(1, 10.0, 1, (0,)),
        Task(2, 4.0, 1, (0,)),
        Task(3, 2.0, 1, (1, 2)),
        Task(4, 5.0),
    ]
    seconds, keys = critical_chain(tasks)
    assert seconds == pytest.approx(13.0) and keys == [0, 1, 3]


def sampling_config(guidance, samplers, n=100):
    return hand_config(
        {"c": {"n": n}},
        generate={"guidance": guidance, "samplers": samplers, "hidden": 64, "blocks": 1},
    )


def test_a_generators_sampling_job_runs_its_cells_on_its_threads():
    """One job per generator: its units are the cells' sums; one thread costs the overhead
    plus every cell, many threads the overhead plus the longest cell (each cell on one
    thread)."""
    from tacgen_lib.estimate.flops import flop_seconds
    from tacgen_lib.estimate.predict import job_prediction

    cfg = sampling_config([1, 3], {"ddim": [5, 25], "ddpm": [100]})
    w = {"corpus": "c", "seed": "0"}
    lines = fit_costs(
        points(
            [("sample_generator", 100, 1.0 + 1e-3 * 100)] * 1
            + [("sample_generator", 10_000, 1.0 + 1e-3 * 10_000)]
        )
    )
    _, units, flops = job_units("sample_generator", cfg, w)
    assert units == pytest.approx(100 * (5 + 25 + 100) * 2)  # sample x step, both guidances
    cells = UNITS["sample_generator"].cells(cfg, w)
    assert len(cells) == 6 and sum(f for _, f in cells) == pytest.approx(flops)
    line = lines["sample_generator"]
    one = [line.per_unit * u + flop_seconds(f, 1) for u, f in cells]
    _, _, serial, _ = job_prediction("sample_generator", cfg, w, 1, lines)
    _, _, wide, _ = job_prediction("sample_generator", cfg, w, 8, lines)
    assert serial == pytest.approx(line.overhead + sum(one))
    assert wide == pytest.approx(line.overhead + max(one))  # the DDPM-100 cell at w = 3


def test_a_gpu_class_moves_only_the_torch_rules_flops():
    from tacgen_lib.estimate.predict import job_prediction

    cfg = sampling_config([3], {"ddim": [50]}, n=1000)
    cfg["generate"].update(steps=1000, batch_size=256)
    w = {"corpus": "c", "seed": "0"}
    lines = fit_costs(
        points(
            [
                (r, u, 1.0 + 1e-3 * u)
                for r in ("train_generator", "sample_generator")
                for u in (10, 10_000)
            ]
        )
    )
    cpu = job_prediction("train_generator", cfg, w, 2, lines)[2]
    gpu = job_prediction("train_generator", cfg, w, 2, lines, gpu_tflops=20.0)[2]
    assert gpu < cpu  # torch training: its FLOPs at the GPU's rate
    assert gpu >= lines["train_generator"].seconds(1000)  # its per-unit cost stays the CPU's
    # the latent sampler is numpy: a GPU does not change it
    assert (
        job_prediction("sample_generator", cfg, w, 1, lines, gpu_tflops=20.0)[2]
        == (job_prediction("sample_generator", cfg, w, 1, lines)[2])
    )
