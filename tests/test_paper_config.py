"""config/paper.yaml says what it runs, and its cluster run fits its time limits and a day.

- Snakemake merges `--configfile` over config/config.yaml recursively: every mapping paper.yaml
  sets that the default also has carries, beside its key, what the merged run gets
  (`[exact]`: these keys only; `[+ default: a, b]`: the default's a, b too), checked here on
  the merged config.
- The paper's backbones are the official checkpoints in models/: a missing file stops the run
  at parse time, naming the key, the file and where it is published. The DAG tests point the
  keys at tiny stand-in files (nothing loads them: a dry run builds the DAG only).
- Every job's requested runtime (tacgen_lib.estimate.resources, as Snakemake evaluates it under
  profiles/slurm's threads) is at least its run-time estimate; the estimate on 8 × 32-core
  nodes is within a day and names its critical path.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from tacgen_lib.estimate.command import checkpoint_override
from tacgen_lib.features.families import OFFICIAL_CHECKPOINTS, BackboneSpec, check_checkpoint_file
from tacgen_lib.io.config import ConfigError

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "config" / "paper.yaml"
CHECKPOINT_KEYS = [
    ("features", "backbones", "vision"),
    ("features", "backbones", "tactile"),
    ("backbones", "families", "dinov2", "vision"),
    ("backbones", "families", "dinov2", "tactile"),
    ("backbones", "families", "mae", "vision"),
    ("backbones", "families", "mae", "tactile"),
]


def merged(*files: Path) -> dict:
    """The config Snakemake runs: each file merged over the default, recursively."""
    from snakemake.utils import update_config

    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    for f in files:
        update_config(config, yaml.safe_load(Path(f).read_text()))
    return config


def mapping_markers(text: str) -> dict[tuple[str, ...], str]:
    """Key path -> the text of the comment on its line (or on the comment line just above),
    for every key of `text` whose value is a mapping."""
    lines = text.splitlines()
    out: dict[tuple[str, ...], str] = {}

    def walk(node: yaml.MappingNode, path: tuple[str, ...]) -> None:
        for key, value in node.value:
            if not isinstance(value, yaml.MappingNode):
                continue
            row = key.start_mark.line
            comment = lines[row].partition("#")[2] if "#" in lines[row] else ""
            above = lines[row - 1].strip() if row else ""
            if above.startswith("#"):
                comment += " " + above
            out[(*path, key.value)] = comment
            walk(value, (*path, key.value))

    walk(yaml.compose(text), ())
    return out


def get(config: dict, path: tuple[str, ...]):
    for k in path:
        config = config[k]
    return config


def test_every_mapping_paper_yaml_merges_says_what_the_run_gets():
    text = PAPER.read_text()
    paper = yaml.safe_load(text)
    default = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    run = merged(PAPER)
    markers = mapping_markers(text)
    checked = 0
    for path, comment in markers.items():
        try:
            in_default = isinstance(get(default, path), dict)
        except (KeyError, TypeError):
            in_default = False
        if not in_default:
            continue  # nothing of the default's merges into it
        where = "config/paper.yaml " + ".".join(path)
        exact = "[exact]" in comment
        plus = re.search(r"\[\+ default: ([^\]]*)\]", comment)
        assert exact != bool(plus), f"{where}: say [exact] or [+ default: ...] beside the key"
        extra = set(get(run, path)) - set(get(paper, path))
        if exact:
            assert not extra, f"{where} says [exact], but the merged run also has {sorted(extra)}"
        else:
            said = {k.strip() for k in plus.group(1).split(",")}
            assert extra == said, f"{where}: the merged run adds {sorted(extra)}, it says {said}"
        checked += 1
    assert checked >= 30  # every merged mapping of the file, not a few


def test_paper_yaml_runs_the_generators_it_lists():
    run = merged(PAPER)
    paper = yaml.safe_load(PAPER.read_text())
    assert run["generate"]["corpora"] == paper["generate"]["corpora"]
    assert len(run["generate"]["corpora"]) == 5
    assert run["pixel"]["corpora"] == paper["pixel"]["corpora"]
    # the DINOv2 family is the main features' backbones (one spec: it reads the main edges)
    for m in ("vision", "tactile"):
        fam = run["backbones"]["families"]["dinov2"][m]
        assert BackboneSpec.from_config(fam) == BackboneSpec.from_config(
            run["features"]["backbones"][m]
        )


def test_paper_reads_official_checkpoints_from_models():
    run = merged(PAPER)
    for path in CHECKPOINT_KEYS:
        ckpt = get(run, path)["checkpoint"]
        assert ckpt.startswith("models/") and Path(ckpt).name in OFFICIAL_CHECKPOINTS, path
    # pretraining is one key away: paper_pretrain.yaml nulls every checkpoint
    pre = merged(PAPER, ROOT / "config" / "paper_pretrain.yaml")
    assert all(get(pre, path)["checkpoint"] is None for path in CHECKPOINT_KEYS)


# ---- the parse-time check of a checkpoint file ---------------------------------------------


def test_missing_official_checkpoint_names_key_file_and_where_it_is_published(tmp_path):
    spec = BackboneSpec(arch="vit_small", checkpoint="models/dinov2_vits14_pretrain.pth")
    with pytest.raises(ConfigError) as err:
        check_checkpoint_file(spec, where="features.backbones.vision", root=tmp_path)
    msg = str(err.value)
    assert "features.backbones.vision.checkpoint" in msg
    assert "dinov2_vits14_pretrain.pth" in msg and str(tmp_path / "models") in msg
    assert "https://dl.fbaipublicfiles.com/dinov2/dinov2_vits14/dinov2_vits14_pretrain.pth" in msg
    assert "checkpoint: null" in msg  # the key that pretrains instead
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "dinov2_vits14_pretrain.pth").write_bytes(b"x")
    check_checkpoint_file(spec, where="features.backbones.vision", root=tmp_path)  # passes


def test_checkpoint_check_of_unknown_names_and_none(tmp_path):
    check_checkpoint_file(BackboneSpec(arch="vit_tiny"), where="x", root=tmp_path)  # none: ok
    with pytest.raises(ConfigError, match="no official release is named 'mine.pth'"):
        check_checkpoint_file(
            BackboneSpec(arch="vit_tiny", checkpoint=str(tmp_path / "mine.pth")), where="x"
        )


# ---- paper.yaml's DAG ------------------------------------------------------------------------


def stand_in_checkpoints(folder: Path, missing: tuple[str, ...] = ()) -> Path:
    """A config merged after paper.yaml pointing every checkpoint key at a tiny file of the
    official name in `folder` (the DAG is built, nothing loads them); the keys in `missing`
    (dotted) at a file that is not there."""
    folder.mkdir(parents=True, exist_ok=True)
    run = merged(PAPER)
    targets = {}
    for path in CHECKPOINT_KEYS:
        name = Path(get(run, path)["checkpoint"]).name
        target = folder / name
        if ".".join(path) in missing:
            target = folder / "absent" / name
        else:
            target.write_bytes(b"stand-in")
        targets[".".join(path)] = target
    out = folder / "checkpoints.yaml"
    out.write_text(yaml.safe_dump(checkpoint_override(targets)))
    return out


@pytest.fixture(scope="module")
def paper_dag(tmp_path_factory):
    """paper.yaml's DAG with profiles/slurm's threads on 32-core nodes (a dry run)."""
    from tacgen_lib.estimate.command import profile_threads
    from tacgen_lib.estimate.dag import dag_jobs

    override = stand_in_checkpoints(tmp_path_factory.mktemp("models"))
    threads = profile_threads(ROOT / "profiles" / "slurm")
    jobs, config = dag_jobs(
        ["config/paper.yaml", str(override)], workdir=ROOT, cores=32, set_threads=threads
    )
    return jobs, config


def test_missing_checkpoint_stops_the_dag_at_parse_time(tmp_path):
    from tacgen_lib.estimate.dag import dag_jobs

    override = stand_in_checkpoints(tmp_path, missing=("backbones.families.mae.tactile",))
    with pytest.raises(Exception) as err:
        dag_jobs(["config/paper.yaml", str(override)], workdir=ROOT)
    msg = str(err.value)
    assert "backbones.families.mae.tactile.checkpoint" in msg, msg
    assert "mae_pretrain_vit_base.pth" in msg and "dl.fbaipublicfiles.com/mae" in msg, msg


def test_paper_dag_jobs_per_rule(paper_dag):
    jobs, _ = paper_dag
    count: dict[str, int] = {}
    for j in jobs:
        count[j.rule] = count.get(j.rule, 0) + 1
    # 5 generator corpora x 5 seeds; one sampling job per generator (36 cells each)
    assert count["train_generator"] == 25 and count["sample_generator"] == 25
    # the official checkpoints: no family pretrains; the DINOv2 family reads the main edges
    assert count["pretrain_backbone"] == 2
    families = {j.wildcards["family"] for j in jobs if j.rule == "family_backbone"}
    assert families == {"resnet", "mae"}


def test_no_paper_job_asks_for_less_time_than_its_estimate(paper_dag):
    """Each job's runtime as Snakemake evaluates it for profiles/slurm (attempt 1) against the
    estimate of that job (same rule, config, wildcards and threads, shipped calibration)."""
    from tacgen_lib.estimate.calibration import fit_costs, load_calibration
    from tacgen_lib.estimate.predict import job_prediction
    from tacgen_lib.estimate.resources import HEADROOM, MIN_RUNTIME_S

    jobs, config = paper_dag
    lines = fit_costs(load_calibration().points)
    short, longest = [], (0.0, "")
    for j in jobs:
        if not j.runs:
            continue
        seconds = job_prediction(j.rule, j.config_of(config), j.wildcards, j.threads, lines)[2]
        assert j.runtime is not None, f"{j.rule} {dict(j.wildcards)}: no runtime resource"
        if j.runtime * 60 < max(MIN_RUNTIME_S, HEADROOM * seconds):
            short.append((j.rule, dict(j.wildcards), j.runtime, seconds))
        longest = max(longest, (seconds, j.rule))
    assert not short, short[:5]
    assert longest[0] > 4 * 3600  # the paper's long jobs are priced, not the floor


def test_paper_estimate_on_eight_nodes_is_within_a_day(paper_dag):
    from tacgen_lib.estimate.calibration import load_calibration
    from tacgen_lib.estimate.command import format_estimate, profile_jobs
    from tacgen_lib.estimate.predict import estimate_run
    from tacgen_lib.estimate.schedule import slurm_machine

    jobs, config = paper_dag
    machine = slurm_machine(8, 32, max_jobs=profile_jobs(ROOT / "profiles" / "slurm"))
    est = estimate_run(jobs, config, load_calibration(), machine)
    assert est.total <= 24 * 3600, format_estimate(est)
    rules = [r for r, _ in est.critical]
    assert "sample_generator" in rules and est.critical_seconds <= est.makespan + 1e-6
    assert "critical path" in format_estimate(est)


def test_estimate_prices_paper_before_the_checkpoints_are_downloaded(tmp_path):
    """make estimate of paper.yaml works before models/ is filled: the missing files are named
    (the run itself still stops on them) and priced through empty stand-ins of their names."""
    import shutil

    from tacgen_lib.estimate.command import (
        missing_checkpoints,
        stand_in_checkpoints,
        validated_config,
    )

    (tmp_path / "config").mkdir()
    for name in ("config.yaml", "paper.yaml"):
        shutil.copy(ROOT / "config" / name, tmp_path / "config" / name)
    config = validated_config(["config/paper.yaml"], tmp_path)
    missing = missing_checkpoints(config, tmp_path)
    assert set(missing) == {".".join(p) for p in CHECKPOINT_KEYS}
    assert missing["backbones.families.mae.vision"] == "models/mae_pretrain_vit_base.pth"
    override = stand_in_checkpoints(missing, config, tmp_path / "stand-ins")
    config = validated_config(["config/paper.yaml", str(override)], tmp_path)
    assert missing_checkpoints(config, tmp_path) == {}
    assert Path(config["features"]["backbones"]["vision"]["checkpoint"]).name == (
        "dinov2_vits14_pretrain.pth"
    )
