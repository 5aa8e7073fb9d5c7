"""The jobs of a config's DAG, as Snakemake itself builds them (never re-implemented here).

`dag_jobs` asks Snakemake (its Python API, snakemake 9) for the whole DAG of a config as if
every output were missing (`--forceall`), and returns one `DagJob` per job: rule, wildcards,
threads, whether the rule is a `localrules` rule, its benchmark path and the jobs it waits
for. Building the DAG reads no output and writes none (no lock is taken); it takes as long as
the dry run of the same config (~10-20 s on 2 cores).

Snakemake's API stops at "print the DAG"; the job objects are reached the way its own
`--d3dag` printer reaches them (`Workflow._prepare_dag`, `_build_dag`, `DAG.dependencies`).
Those names are internal to Snakemake 9 (pinned `>=9,<10` in pyproject.toml), which is why they
are used in this one function only.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["DagJob", "base_rule", "dag_jobs"]


@dataclass(frozen=True)
class DagJob:
    """One job of the DAG: `jobid` (unique in its DAG), `rule`, `wildcards` (name -> text),
    `threads` (as Snakemake resolves them for the given core count), `local` (a `localrules`
    rule: runs on the submitting host under SLURM), `benchmark` (its benchmark file, relative to
    the working directory; None for a rule without one, e.g. the target rule `all`), `log`
    (its first log file, likewise), `runs` (False for a rule without a script/shell/run, such as `all`: it costs nothing) and
    `deps` (jobids of the jobs it waits for), `runtime` (its `runtime` resource in minutes as
    Snakemake evaluates it for the first attempt: its SLURM time limit; None without one)."""

    jobid: int
    rule: str
    wildcards: Mapping[str, str] = field(default_factory=dict)
    threads: int = 1
    local: bool = False
    benchmark: str | None = None
    log: str | None = None
    runs: bool = True
    deps: tuple[int, ...] = ()
    setting: str | None = None
    config: Mapping[str, Any] | None = None
    runtime: int | None = None

    def config_of(self, run_config: Mapping[str, Any]) -> Mapping[str, Any]:
        """The config the job's units are counted from: its setting's, else the run's."""
        return run_config if self.config is None else self.config


def dag_jobs(
    configfiles: list[str | os.PathLike[str]] | None = None,
    *,
    workdir: str | os.PathLike[str] = ".",
    snakefile: str | os.PathLike[str] = "Snakefile",
    cores: int = 2,
    targets: list[str] | None = None,
    set_threads: Mapping[str, int] | None = None,
) -> tuple[list[DagJob], dict[str, Any]]:
    """Every job of the workflow's DAG for `configfiles` (relative to `workdir`; merged over the
    Snakefile's `configfile:` as `--configfile` does), with `--forceall`, and the merged config
    as the workflow validated it (rules/common.smk: `workflow_config.validate_config`).

    `cores` caps each job's threads as `--cores` does; `set_threads` (rule -> threads)
    overrides rules' threads as `--set-threads` (or a profile's `set-threads:`) does. `targets` default to the default target
    (`rule all`). Raises the Snakemake error (naming the config key or rule) if the DAG cannot be
    built.
    """
    from snakemake.api import SnakemakeApi
    from snakemake.settings.types import (
        ConfigSettings,
        DAGSettings,
        OutputSettings,
        Quietness,
        ResourceSettings,
    )

    workdir = Path(workdir).absolute()
    files = [(workdir / f if not Path(f).is_absolute() else Path(f)) for f in configfiles or []]
    for f in files:
        if not f.exists():
            raise FileNotFoundError(f"{f}: config file not found")
    here = Path.cwd()
    try:
        with SnakemakeApi(OutputSettings(quiet={Quietness.ALL}, enable_file_logging=False)) as api:
            wf_api = api.workflow(
                resource_settings=ResourceSettings(
                    cores=cores, overwrite_threads=dict(set_threads or {})
                ),
                config_settings=ConfigSettings(configfiles=files),
                snakefile=workdir / snakefile,
                workdir=workdir,
            )
            dag_settings = DAGSettings(forceall=True, targets=frozenset(targets or ()))
            wf_api.dag(dag_settings)  # installs the DAG settings on the workflow
            workflow = wf_api._workflow
            workflow._prepare_dag(
                forceall=True, ignore_incomplete=True, lock_warn_only=True, nolock=True
            )
            workflow._build_dag()
            dag = workflow.dag
            snake_jobs = list(dag.jobs)
            ids = {job: i for i, job in enumerate(snake_jobs)}
            local_rules = set(getattr(workflow, "_localrules", set()))
            module_configs: dict[str, dict[str, Any]] = {}  # one plain copy per setting
            setting_of = {
                rule.name: _setting_rule(rule, module_configs)
                for rule in {job.rule for job in snake_jobs}
            }
            jobs = [
                DagJob(
                    jobid=ids[job],
                    rule=setting_of[job.rule.name][0],
                    wildcards={k: str(v) for k, v in job.wildcards_dict.items()},
                    threads=int(job.threads),
                    local=job.rule.name in local_rules,
                    benchmark=str(job.benchmark) if job.benchmark is not None else None,
                    log=str(job.log[0]) if job.log else None,
                    runs=not job.rule.norun,
                    deps=tuple(sorted(ids[d] for d in dag.job_dependencies(job))),
                    setting=setting_of[job.rule.name][1],
                    config=setting_of[job.rule.name][2],
                    runtime=_runtime(job),
                )
                for job in snake_jobs
            ]
            config = _plain(workflow.config)
    finally:
        os.chdir(here)
    return jobs, config


def _runtime(job: Any) -> int | None:
    """A Snakemake job's `runtime` resource (minutes), None where it has none."""
    value = job.resources.get("runtime")
    return int(value) if isinstance(value, int | float) else None


def _setting_rule(
    rule: Any, module_configs: dict[str, dict[str, Any]]
) -> tuple[str, str | None, dict[str, Any] | None]:
    """(main rule name, module name, module config) of a Snakemake rule; (name, None, None)
    for a rule of the run itself. `module_configs` keeps one plain copy of each module's
    config, shared by its rules' jobs."""
    module_config = (getattr(rule, "module_globals", None) or {}).get("config")
    setting = ((module_config or {}).get("cost") or {}).get("setting")
    if not setting:
        return rule.name, None, None
    name = setting["module"]
    if name not in module_configs:
        module_configs[name] = _plain(module_config)
    return base_rule(rule.name, module_config), name, module_configs[name]


def _plain(value: Any) -> Any:
    """Snakemake's config as plain dicts and lists (it may hand out its own mapping types)."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def base_rule(rule: str, config: Mapping[str, Any]) -> str:
    """The main rule a job of a setting's module runs: its name without the module prefix
    (`config` is the job's own config; a main-run job's rule is returned as it is)."""
    setting = (config.get("cost") or {}).get("setting")
    if not setting:
        return rule
    return rule.removeprefix(f"{setting['module']}_")
