"""Running the workflow from tests: a copy of the repository, Snakemake on config/test.yaml.

Shared by the workflow, align, probes and SLURM test modules (imported by name: pytest puts
tests/ on sys.path).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import yaml

from tacgen_lib.io.run_compare import copy_workflow

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake"]


def copy_tree(dest: Path) -> Path:
    return copy_workflow(ROOT, dest)


def copy_run(src: Path, dest: Path) -> Path:
    """A copy of the repository with the finished run of `src` (results and .snakemake, mtimes
    kept), so Snakemake sees nothing to do until the test changes something."""
    work = copy_tree(dest)
    shutil.copytree(src / "results", work / "results")
    shutil.copytree(src / ".snakemake", work / ".snakemake")
    return work


def smk(
    workdir: Path, *args: str, check: bool = True, timeout: int = 600
) -> subprocess.CompletedProcess:
    cmd = [*SNAKEMAKE, "--cores", "2", "--configfile", "config/test.yaml", *args]
    proc = subprocess.run(cmd, cwd=workdir, capture_output=True, text=True, timeout=timeout)
    if check and proc.returncode != 0:
        raise AssertionError(
            f"snakemake {' '.join(args)} failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-8000:]}"
        )
    return proc


def planned_rules(workdir: Path, *args: str) -> dict[str, int]:
    """Rules a dry run would execute, with job counts (from --summary-like job stats)."""
    return plan_of(smk(workdir, "--dry-run", *args))


def plan_of(proc: subprocess.CompletedProcess) -> dict[str, int]:
    """The rules and job counts in the job stats a dry run printed."""
    out = proc.stdout + proc.stderr
    if "Nothing to be done" in out:
        return {}
    counts: dict[str, int] = {}
    in_table = False
    for line in out.splitlines():
        parts = line.split()
        if parts[:2] == ["job", "count"]:
            in_table = True
            continue
        if in_table:
            if len(parts) == 2 and parts[1].isdigit() and parts[0] != "total":
                counts[parts[0]] = int(parts[1])
            elif parts and parts[0] == "total":
                break
    return counts


def edge_hashes(workdir: Path) -> dict[str, str]:
    return {
        str(p.relative_to(workdir)): json.loads(p.read_text())["sha256"]
        for p in sorted((workdir / "results").rglob("*.sha256.json"))
        if "/shards/" not in str(p)
    }


def merged_config() -> dict:
    """config/config.yaml extended by config/test.yaml, as Snakemake merges them."""

    def merge(a: dict, b: dict) -> dict:
        out = dict(a)
        for k, v in b.items():
            out[k] = merge(a[k], v) if isinstance(v, dict) and isinstance(a.get(k), dict) else v
        return out

    base = yaml.safe_load((ROOT / "config/config.yaml").read_text())
    return merge(base, yaml.safe_load((ROOT / "config/test.yaml").read_text()))


def validated(overlay: str | None = None) -> dict:
    """config/config.yaml (merged with an overlay of config/, as Snakemake merges), validated
    against the schema (its defaults filled in)."""
    from snakemake.utils import update_config

    from tacgen_lib.workflow_config import validate_config

    cfg = yaml.safe_load((ROOT / "config/config.yaml").read_text())
    if overlay:
        update_config(cfg, yaml.safe_load((ROOT / "config" / overlay).read_text()))
    cfg["scenes_file"] = str(ROOT / cfg["scenes_file"])
    return validate_config(cfg, ROOT / "config" / "config.schema.yaml")


def hand_config(corpora: dict | None = None, **sections: dict) -> dict:
    """A config as the estimate reads it: config/test.yaml's, validated (`validated`: the
    schema's defaults filled in), with each corpus of `corpora` a copy of its sim_paired with
    the keys given, and each of `sections` updated with the keys given."""
    cfg = validated("test.yaml")
    for name, keys in (corpora or {}).items():
        cfg["corpora"][name] = {**cfg["corpora"]["sim_paired"], **keys}
    for name, keys in sections.items():
        cfg[name] = {**cfg[name], **keys}
    return cfg


def report_page(path: Path) -> str:
    """A report page's HTML as its reader's text runs: without the line-break opportunities
    (``<wbr>``) that `tacgen_lib.report.tables.cell_html` puts inside long identifiers."""
    return Path(path).read_text().replace("<wbr>", "")
