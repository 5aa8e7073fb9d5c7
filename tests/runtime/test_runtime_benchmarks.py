"""Benchmark files are read as Snakemake writes them, and bad ones are named."""

import pytest

from tacgen_lib.runtime.benchmarks import benchmark_table, read_benchmark

HEADER = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"


def test_read_benchmark_means_repeats(tmp_path):
    path = tmp_path / "b.tsv"
    path.write_text(
        HEADER
        + "2.0\t0:00:02\t100\t1\t1\t1\t0\t0\t50\t1.5\n4.0\t0:00:04\t300\t1\t1\t1\t0\t0\t50\t2.5\n"
    )
    b = read_benchmark(path)
    assert (b.wall, b.cpu, b.max_rss_mb) == (3.0, 2.0, 200.0)


def test_benchmark_table_names_rule_and_job(tmp_path):
    job = tmp_path / "probe" / "mass" / "protocol~raw" / "seed~42.tsv"
    job.parent.mkdir(parents=True)
    job.write_text(HEADER + "1.25\t0:00:01\t10\t1\t1\t1\t0\t0\t50\t1.0\n")
    (tmp_path / "make_splits.tsv").write_text(HEADER + "0.5\t0:00:00\t10\t1\t1\t1\t0\t0\t5\t0.4\n")
    table = benchmark_table(tmp_path)
    assert list(table["rule"]) == ["make_splits", "probe"]
    assert list(table["job"]) == ["make_splits", "mass/protocol~raw/seed~42"]
    assert list(table["wall"]) == [0.5, 1.25]
    assert benchmark_table(tmp_path / "absent").empty


def test_unreadable_benchmark_is_named(tmp_path):
    path = tmp_path / "empty.tsv"
    path.write_text("")
    with pytest.raises(ValueError, match="empty.tsv"):
        read_benchmark(path)


def test_a_cell_timed_by_its_job_reads_like_a_snakemake_benchmark(tmp_path):
    from tacgen_lib.runtime.benchmarks import write_benchmark

    path = tmp_path / "sample_generator" / "c" / "0_ddim_1_25.tsv"
    write_benchmark(path, wall=3725.5, cpu=3600.25)
    b = read_benchmark(path)
    assert b.wall == 3725.5 and b.cpu == 3600.25
    assert path.read_text().splitlines()[1].split("\t")[1] == "1:02:05"  # h:m:s
    assert not list(path.parent.glob(".*.tmp"))  # written atomically
