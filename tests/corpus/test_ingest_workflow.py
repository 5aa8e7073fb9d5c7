"""The real-data rules on the TVL folders as published (tests/fixtures_real.py): `ingest_tvl`
and `background_subtract` run by Snakemake on a config that points at them, in a copy of the
repository: the SSVTP background read from a stand-in for the TVL code clone, the pairs the
authors' loader leaves out counted in the log, and an HCT row without a background ingested,
then refused by name where subtraction needs it."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
import yaml
from fixtures_real import write_hct_fixture, write_ssvtp_fixture
from snakemake_run import SNAKEMAKE, copy_tree

from tacgen_lib.io import edges

pytestmark = pytest.mark.workflow


def test_ingest_rules_read_the_published_layout(tmp_path: Path) -> None:
    data, code, bare = tmp_path / "tvl", tmp_path / "tvl-code", tmp_path / "tvl-bare"
    write_ssvtp_fixture(data, n=12, code=code)
    write_hct_fixture(data, n_traj=2, per_traj=4)
    # an HCT copy whose first trajectory has no background, nor the fallback above it
    write_hct_fixture(bare, n_traj=2, per_traj=4)
    (bare / "hct" / "data1" / "0-1702507215.615537" / "background.png").unlink()
    (bare / "hct" / "digit_background.png").unlink()
    (bare / "hct" / "data2" / "1-1702507276.865537").rename(bare / "unused")  # took the fallback
    for name in ("train.csv", "test.csv"):
        (bare / "hct" / "data2" / name).unlink()
    (bare / "hct" / "data2" / "contact.json").unlink()

    work = copy_tree(tmp_path / "repo")
    corpora = {
        "ssvtp": {"kind": "ssvtp", "root": str(data), "background": str(code)},
        "hct": {"kind": "hct", "root": str(data)},
        "hct_bare": {"kind": "hct", "root": str(bare)},
    }
    (work / "config" / "tvl.yaml").write_text(yaml.safe_dump({"corpora": corpora}))
    targets = [f"results/preprocess/{c}/clip128.parquet" for c in corpora]
    proc = subprocess.run(
        [*SNAKEMAKE, *targets, "--cores", "2", "--keep-going"]
        + ["--configfile", "config/test.yaml", "config/tvl.yaml"],
        cwd=work,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode != 0  # hct_bare cannot be background-subtracted
    results = work / "results"
    for corpus, rows in (("ssvtp", 12), ("hct", 8), ("hct_bare", 4)):
        assert len(edges.read(results / f"corpus/{corpus}/samples.parquet")) == rows
    for corpus in ("ssvtp", "hct"):
        assert len(edges.read(results / f"preprocess/{corpus}/clip128.parquet")) == (
            12 if corpus == "ssvtp" else 8
        )
    assert not (results / "preprocess/hct_bare/clip128.parquet").exists()

    log = (results / "logs/ingest_tvl/ssvtp.log").read_text()
    assert "ssvtp: 12 samples, 1 sensor backgrounds" in log
    assert "skipped 1 pairs listed in neither train.csv nor test.csv: ssvtp-000012" in log
    assert "skipped 2 listed pairs with missing files: ssvtp-000013" in log
    log = (results / "logs/ingest_tvl/hct_bare.log").read_text()
    assert "hct_bare: 4 samples have no tactile background" in log
    log = (results / "logs/background_subtract/hct_bare/clip128.log").read_text()
    assert "rule background_subtract" in log and "4 of 4 samples" in log
    assert "'hct_bare-data1-00000'" in log and "'hct_bare-data1-00003'" in log
