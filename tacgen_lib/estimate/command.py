"""The run-time estimate's command: `python -m tacgen_lib.estimate` (`make estimate`) prints the
predicted per-rule and total wall time of a config (`tacgen_lib.estimate.predict`) on N local
cores or on a SLURM cluster of K nodes, before running it.

    .venv/bin/python -m tacgen_lib.estimate --configfile config/paper.yaml --cores 2
    .venv/bin/python -m tacgen_lib.estimate --configfile config/paper.yaml \\
        --slurm-nodes 8 --cores-per-node 32

Checkpoints a config names but that are not downloaded yet are priced as if they were
(`stand_in_checkpoints`); the run itself still stops on them. Every setting is read from the
validated config (`validated_config`; the DAG's from the workflow, which validates it in
rules/common.smk), whose defaults are the schema's: the estimate supplies none of its own.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from tacgen_lib.estimate.calibration import MissingCalibrationError
from tacgen_lib.estimate.dag import dag_jobs
from tacgen_lib.estimate.predict import Estimate, choose_calibration, estimate_run
from tacgen_lib.estimate.schedule import Machine, local_machine, slurm_machine
from tacgen_lib.estimate.units import MissingUnitsError

__all__ = [
    "profile_threads",
    "profile_jobs",
    "merged_config",
    "validated_config",
    "missing_checkpoints",
    "stand_in_checkpoints",
    "checkpoint_override",
    "format_estimate",
    "write_table",
    "main",
]


def _profile(profile: str | os.PathLike[str]) -> dict[str, Any]:
    path = Path(profile) / "config.yaml"
    if not str(profile) or not path.is_file():
        return {}
    import yaml

    return yaml.safe_load(path.read_text()) or {}


def profile_threads(profile: str | os.PathLike[str]) -> dict[str, int]:
    """`set-threads:` of a Snakemake profile folder (its config.yaml); {} without one."""
    data = _profile(profile)
    return {str(k): int(v) for k, v in (data.get("set-threads") or {}).items()}


def profile_jobs(profile: str | os.PathLike[str], default: int = 50) -> int:
    """`jobs:` of a Snakemake profile folder (jobs queued or running at once); `default`
    without one."""
    return int(_profile(profile).get("jobs", default))


def merged_config(
    configfiles: Sequence[str | os.PathLike[str]], workdir: str | os.PathLike[str] = "."
) -> dict[str, Any]:
    """config/config.yaml with `configfiles` merged over it as Snakemake's `--configfile`
    does (recursively, key by key), before the workflow's own additions and validation."""
    import yaml
    from snakemake.utils import update_config

    config = yaml.safe_load((Path(workdir) / "config" / "config.yaml").read_text()) or {}
    for f in configfiles:
        path = Path(f) if Path(f).is_absolute() else Path(workdir) / f
        update_config(config, yaml.safe_load(path.read_text()) or {})
    return config


def validated_config(
    configfiles: Sequence[str | os.PathLike[str]], workdir: str | os.PathLike[str] = "."
) -> dict[str, Any]:
    """`merged_config` held to this repository's schema and given its defaults
    (`io.config.validate_schema`, the ground floor of the workflow's validation): a bad value
    is refused naming its key. The cross-references (corpora, scenes, variants) are checked
    when the workflow builds the DAG (`dag_jobs`; rules/common.smk runs
    `tacgen_lib.workflow_config.validate_config`)."""
    from tacgen_lib.io.config import validate_schema
    from tacgen_lib.io.schema import SCHEMA_PATH

    config = merged_config(configfiles, workdir)
    sources = " + ".join(["config/config.yaml", *map(str, configfiles)])
    return validate_schema(config, SCHEMA_PATH, source=sources)


def missing_checkpoints(
    config: Mapping[str, Any], workdir: str | os.PathLike[str] = "."
) -> dict[str, str]:
    """Config key of every backbone (main features, families run) of a validated `config`
    (`validated_config`) whose checkpoint file is not here (the run would stop on it:
    `families.check_checkpoint_file`) -> its checkpoint."""
    from tacgen_lib.features.families import BackboneSpec, check_checkpoint_file
    from tacgen_lib.io.config import ConfigError

    specs = {f"features.backbones.{m}": s for m, s in config["features"]["backbones"].items()}
    families = config["backbones"]["families"]
    for name in config["backbones"]["run"]:
        for m, spec in families.get(name, {}).items():  # an unknown name is the workflow's
            specs[f"backbones.families.{name}.{m}"] = spec
    missing = {}
    for key, spec in specs.items():
        try:
            check_checkpoint_file(BackboneSpec.from_config(spec), where=key, root=workdir)
        except ConfigError:
            missing[key] = str(spec["checkpoint"])
    return missing


def stand_in_checkpoints(
    missing: Mapping[str, str], config: Mapping[str, Any], folder: str | os.PathLike[str]
) -> Path:
    """A config file in `folder` pointing each missing checkpoint key at an empty file of the
    same name there: the DAG a run would have once the files are downloaded (building it reads
    no checkpoint). For the estimate only; the run itself still stops on the missing file."""
    import yaml

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stand_ins = {}
    for key in missing:
        spec: Any = config
        for k in key.split("."):
            spec = spec[k]
        stand_in = folder / Path(spec["checkpoint"]).name
        stand_in.touch()
        stand_ins[key] = stand_in
    out = folder / "stand_in_checkpoints.yaml"
    out.write_text(yaml.safe_dump(checkpoint_override(stand_ins)))
    return out


def checkpoint_override(checkpoints: Mapping[str, str | os.PathLike[str]]) -> dict[str, Any]:
    """The config override that sets each backbone key's (dotted, e.g.
    `backbones.families.mae.tactile`) `checkpoint` to its file."""
    override: dict[str, Any] = {}
    for key, path in checkpoints.items():
        node = override
        for k in key.split("."):
            node = node.setdefault(k, {})
        node["checkpoint"] = str(path)
    return override


def format_estimate(est: Estimate) -> str:
    """The per-rule table and the total, as printed by the command."""
    table = est.per_rule.copy()
    lines = [
        f"Run-time estimate on {est.machine}",
        f"calibration: {est.source}",
        "",
        f"{'rule':28s} {'jobs':>5s} {'thr':>3s} {'job-seconds':>12s} {'start':>8s} {'end':>8s}  unit",
    ]
    for r in table.itertuples():
        flag = "" if r.per_unit_fitted else " *"
        lines.append(
            f"{r.rule + flag:28s} {r.jobs:5d} {r.threads:3d} {r.job_seconds:12.1f} "
            f"{r.start_s:8.1f} {r.end_s:8.1f}  {r.unit}"
        )
    if not table["per_unit_fitted"].all():
        lines += [
            "* per-unit cost not identified (the calibration measured one size of these jobs, "
            "or sizes too close): flat at the measured mean, a lower bound for larger jobs"
        ]
    chain = " -> ".join(f"{rule} ({seconds:.0f} s)" for rule, seconds in est.critical)
    lines += [
        "",
        f"critical path (longest chain of dependent jobs, {est.critical_seconds:.0f} s = "
        f"{est.critical_seconds / 3600:.2f} h; no core count shortens it): {chain}",
        f"jobs: {int(table['jobs'].sum())}, job-seconds: {table['job_seconds'].sum():.0f} s",
        f"scheduled jobs (makespan): {est.makespan:.0f} s; workflow overhead: {est.overhead:.0f} s",
        f"total predicted wall time: {est.total:.0f} s ({est.total / 60:.1f} min, "
        f"{est.total / 3600:.2f} h)",
    ]
    return "\n".join(lines)


def write_table(est: Estimate, out: str | os.PathLike[str]) -> None:
    """The per-rule table with a `total` row (machine and source in columns) to `out`: .parquet,
    .csv or .tsv by suffix; written atomically (temp file + rename)."""
    out = Path(out)
    table = est.per_rule.copy()
    total = {
        "rule": "total",
        "jobs": int(table["jobs"].sum()),
        "threads": int(table["threads"].max()),
        "unit": "wall seconds incl. workflow overhead",
        "units": float("nan"),
        "job_seconds": float(table["job_seconds"].sum()),
        "start_s": 0.0,
        "end_s": est.total,
        "per_unit_fitted": bool(table["per_unit_fitted"].all()),
    }
    table = pd.concat([table, pd.DataFrame([total])], ignore_index=True)
    table["machine"] = est.machine
    table["source"] = est.source
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    if out.suffix == ".parquet":
        table.to_parquet(tmp, index=False)
    elif out.suffix in (".csv", ".tsv"):
        table.to_csv(tmp, index=False, sep="," if out.suffix == ".csv" else "\t")
    else:
        raise ValueError(f"--out {out}: use a .parquet, .csv or .tsv file")
    tmp.replace(out)


def _parser() -> argparse.ArgumentParser:
    """The command line of `main` (README, "Cost of accuracy and the run-time estimate")."""
    parser = argparse.ArgumentParser(
        prog="python -m tacgen_lib.estimate",
        description="Predict per-rule and total wall time of a config's DAG before running it.",
    )
    parser.add_argument(
        "--configfile", action="append", default=[], help="config merged over the default"
    )
    parser.add_argument("--cores", type=int, default=2, help="local cores (default 2)")
    parser.add_argument("--slurm-nodes", type=int, default=None, help="SLURM nodes K")
    parser.add_argument("--cores-per-node", type=int, default=32, help="cores per SLURM node")
    parser.add_argument(
        "--queue-s", type=float, default=30.0, help="SLURM queue + start seconds per job"
    )
    parser.add_argument(
        "--max-jobs",
        type=int,
        default=None,
        help="SLURM jobs at once (default: the profile's `jobs:`)",
    )
    parser.add_argument(
        "--gpu-tflops",
        type=float,
        default=None,
        help="a GPU class: the FLOPs of the rules whose model runs in torch at this effective "
        "rate (TFLOP/s; an assumption until a GPU run calibrates it), their other costs the "
        "CPU's",
    )
    parser.add_argument(
        "--profile",
        default="profiles/slurm",
        help="SLURM profile whose `set-threads:` apply (default profiles/slurm; '' for none)",
    )
    parser.add_argument(
        "--calibration", default=None, help="a calibration folder (default: last run, else shipped)"
    )
    parser.add_argument("--benchmarks", default="results/benchmarks", help="the last run's folder")
    parser.add_argument(
        "--benchmarks-config",
        default=None,
        help="the config the last run used (default: read from its Snakemake log)",
    )
    parser.add_argument(
        "--load-factor",
        type=float,
        default=1.0,
        help="wall here over wall on idle cores (default 1: idle; 6-10 with a dozen other "
        "jobs sharing 2 cores)",
    )
    parser.add_argument(
        "--speed-factor",
        type=float,
        default=1.0,
        help="CPU seconds here per calibration CPU second (e.g. 0.5 on a CPU with AVX-512)",
    )
    parser.add_argument("--workdir", default=".", help="the workflow's directory")
    parser.add_argument("--out", default=None, help="write the per-rule table (.parquet/.csv/.tsv)")
    return parser


def _machine(args: argparse.Namespace) -> tuple[Machine, str, int, dict]:
    """The machine the DAG is priced on, its label, the most cores one job may take, and the
    SLURM profile's thread counts (none on a local machine)."""
    if not args.slurm_nodes:
        return local_machine(args.cores), f"{args.cores} local cores", args.cores, {}
    machine = slurm_machine(
        args.slurm_nodes,
        args.cores_per_node,
        queue_s=args.queue_s,
        max_jobs=args.max_jobs,
        local_cores=args.cores,
    )
    label = (
        f"SLURM, {args.slurm_nodes} nodes x {args.cores_per_node} cores, {args.queue_s:g} s "
        f"queue per job, <= {args.max_jobs} jobs at once, localrules on {args.cores} cores, "
        f"threads of {args.profile or 'the rules'}"
    )
    threads = profile_threads(Path(args.workdir) / args.profile)
    return machine, label, args.cores_per_node, threads


def _speed_words(args: argparse.Namespace) -> str:
    """What the label adds for a load, a speed factor and an assumed GPU rate."""
    words = ""
    if args.load_factor != 1.0:
        words += f", load factor {args.load_factor:g}"
    if args.speed_factor != 1.0:
        words += f", x{args.speed_factor:g} the calibration CPU's seconds"
    if args.gpu_tflops is not None:
        words += (
            f", a GPU per job whose model runs in torch at an assumed {args.gpu_tflops:g} "
            "TFLOP/s effective (not calibrated)"
        )
    return words


def _print_missing(missing: dict) -> None:
    """Name the checkpoint files a run would stop on, and where each is published."""
    from tacgen_lib.features.families import OFFICIAL_CHECKPOINTS

    print(
        f"\nnote: {len(missing)} checkpoint keys name files that are not here; priced as if "
        "they were, but a run stops at parse time until they are downloaded:"
    )
    for key, path in missing.items():
        where = OFFICIAL_CHECKPOINTS.get(Path(path).name, "no official release of that name")
        print(f"  {key}.checkpoint: {path} ({where})")


def main(argv: Sequence[str] | None = None) -> Estimate:
    """Price a config's DAG on a local machine or a SLURM cluster and print the estimate."""
    args = _parser().parse_args(argv)

    if args.max_jobs is None:
        args.max_jobs = profile_jobs(Path(args.workdir) / args.profile)
    machine, label, cap, set_threads = _machine(args)
    # official checkpoints not downloaded yet: priced as if they were (a run stops on them)
    validated = validated_config(args.configfile, args.workdir)
    missing = missing_checkpoints(validated, args.workdir)
    with tempfile.TemporaryDirectory(prefix="tacgen-estimate-") as tmp:
        extra = [str(stand_in_checkpoints(missing, validated, tmp))] if missing else []
        jobs, config = dag_jobs(
            [*args.configfile, *extra], workdir=args.workdir, cores=cap, set_threads=set_threads
        )
    calibration = choose_calibration(
        calibration=args.calibration,
        benchmarks=args.benchmarks,
        benchmarks_config=args.benchmarks_config,
        workdir=args.workdir,
    )
    configs = " + ".join(["config/config.yaml", *args.configfile])
    label += _speed_words(args)
    try:
        est = estimate_run(
            jobs,
            config,
            calibration,
            machine,
            machine_label=f"{label} ({configs})",
            speed=args.speed_factor * args.load_factor,
            gpu_tflops=args.gpu_tflops,
        )
    except (MissingCalibrationError, MissingUnitsError) as exc:
        # what to run is in the message; a traceback would only hide it
        raise SystemExit(f"estimate: {exc}") from None
    print(format_estimate(est))
    if missing:
        _print_missing(missing)
    if args.out:
        write_table(est, args.out)
        print(f"per-rule table: {args.out}", file=sys.stderr)
    return est


if __name__ == "__main__":
    main()
