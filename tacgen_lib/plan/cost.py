"""The cost sweep's plan (docs/cost.md): the knobs of config `cost.knobs`, their settings' runs,
and what each setting's points read (rules/cost.smk).

`tacgen_lib.cost.knobs.KNOBS` is the one table of knobs. A swept knob's every setting (and
replicate) is a run of this workflow with the knob's config keys set, whose copies of the main
rules the knob reruns write under `results/cost/{knob}/{setting}/` (`replace_prefix`); free
knobs (the backbone families, the generator's steps and samplers, the policy sweep) are the
stages' own grids and rerun nothing: a setting run is a cell of the grid (per seed), read from
the stage's summary.

The settings' modules are Snakemake source: `CostPlan.modules_source` writes one `module`
statement and one `use rule ... from ... as ...` statement per setting run, and
rules/cost_common.smk includes that text from the file `write_source` keeps for it.
"""

from __future__ import annotations

import hashlib
import os
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from tacgen_lib.cost.knobs import (
    KNOBS,
    knob_bootstrap,
    knob_metrics,
    knob_settings,
    moved_path,
    shared_runs,
)
from tacgen_lib.features.settings import backbones_pretrained
from tacgen_lib.plan.cost_files import FREE_PLANS, SETTING_FILES, generate_subject
from tacgen_lib.plan.stages import StagePlans

COST_POINTS = "results/cost/points/{knob}.parquet"
#: where the settings' modules are written, under the run's working directory: Snakemake's own
#: state folder (git-ignored, outside `results/`, remade by any parse that needs it)
COST_MODULES_DIR = ".snakemake/cost_modules"


@dataclass(frozen=True)
class CostPlan:
    """config cost: each knob's setting runs (a setting that is the same run as another
    knob's runs once; an unknown knob stops here) and the free knobs the run's grids vary."""

    config: Mapping[str, Any]
    stages: StagePlans
    runs: list[Any]

    @classmethod
    def from_config(cls, config: Mapping[str, Any], stages: StagePlans) -> CostPlan:
        knobs = config["cost"]["knobs"]
        runs = shared_runs(
            [
                run
                for name, entry in knobs.items()
                for run in knob_settings(name, entry or {}, config)
            ]
        )
        return cls(config, stages, runs)

    @cached_property
    def settings(self) -> Mapping[str, Any]:
        return self.config["cost"]

    @cached_property
    def knob_config(self) -> Mapping[str, Any]:
        return self.settings["knobs"]

    def knob_runs(self, knob: str) -> list[Any]:
        """A swept knob's setting runs (none for a free knob)."""
        return [r for r in self.runs if r.knob == knob]

    @cached_property
    def swept(self) -> list[str]:
        return [k for k in self.knob_config if self.knob_runs(k)]

    @cached_property
    def free(self) -> list[str]:
        """The free knobs whose stage runs (the backbone-family knob compares the families
        the run makes: more than one)."""
        s = self.stages
        stage_runs = {
            "generate": bool(s.generate.corpora),
            "policy": s.policy.on,
            "features": len(s.families.settings.run) > 1 and bool(s.families.settings.probes),
        }
        return [
            k
            for k, knob in KNOBS.items()
            if knob.free
            and stage_runs[knob.stage]
            and (k in self.knob_config or self.settings["grid_knobs"])
        ]

    def modules(self) -> dict[str, tuple[Any, list[str]]]:
        """One module per setting run: its run and the main rules it reruns."""
        modules: dict[str, tuple[Any, set[str]]] = {}
        for run in self.runs:
            modules.setdefault(run.module, (run, set()))[1].update(KNOBS[run.knob].reruns)
        return {m: (run, sorted(rules)) for m, (run, rules) in modules.items()}

    def module_config(self, module: str) -> Mapping[str, Any]:
        """The config of a setting's module (its run's: the knob's keys set)."""
        return self.modules()[module][0].config

    def modules_source(self, plan: str, snakefile: str) -> str:
        """The settings' modules as Snakemake source, one block per setting run: a `module`
        statement loading `snakefile` with the run's config and its literal `replace_prefix`,
        then `use rule <the main rules its knobs rerun> from <module> as <module>_*`.

        `plan` is the name the including rule file gives this plan (its `module_config` gives
        each module's config); `snakefile` the Python expression there for the file each
        module loads (rules/stages.smk). Only a header comment when nothing is swept."""
        out = [
            "# Generated from config cost.knobs by tacgen_lib.plan.cost.CostPlan.modules_source",
            "# and included by rules/cost_common.smk: the cost sweep's setting runs, a module",
            "# each (docs/cost.md). Not to be edited: another sweep is another file.",
        ]
        for module, (run, rules) in self.modules().items():
            prefixes = "".join(
                f"\n            {old!r}: {new!r}," for old, new in run.replace_prefix.items()
            )
            out += [
                "",
                "",
                f"module {module}:",
                f"    snakefile:\n        {snakefile}",
                f"    config:\n        {plan}.module_config({module!r})",
                f"    replace_prefix:\n        {{{prefixes}\n        }}",
                "",
                "",
                f"use rule {', '.join(rules)} from {module} as {module}_*",
            ]
        return "\n".join(out) + "\n"

    def knobs(self) -> list[str]:
        """The knobs the page shows: the swept ones, then the free ones."""
        return self.swept + [k for k in self.free if k not in self.swept]

    def points(self, wildcards: Any = None) -> list[str]:
        return [COST_POINTS.format(knob=k) for k in self.knobs()]

    def setting_plan(self, knob: str) -> list[dict[str, Any]]:
        """Per setting run of a knob: label, x position, default flag, replicate, its edges by
        role (verified edges; a free knob's plain summary tables under `tables`), its benchmark
        files (a swept setting's own paths) and the reader's options."""
        if KNOBS[knob].free:
            return FREE_PLANS[KNOBS[knob].reads](self.stages, knob, self.knob_config)
        plan = []
        for run in self.knob_runs(knob):
            edges, benchmarks = SETTING_FILES[KNOBS[knob].reads](
                self.stages, self.knob_config[knob], run, self.settings
            )
            plan.append(
                {
                    "label": run.label,
                    "number": run.number,
                    "is_default": run.is_default,
                    "rep": run.rep,
                    "edges": {
                        role: [moved_path(p, run.replace_prefix) for p in paths]
                        for role, paths in edges.items()
                    },
                    "tables": {},
                    "benchmarks": [moved_path(b, run.replace_prefix) for b in benchmarks],
                    "options": {"pretraining": backbones_pretrained(run.config["features"])},
                }
            )
        return plan

    def knob_options(self, knob: str) -> dict[str, Any]:
        """What a knob's reader needs from the run's config (resamples, seed, metrics; a
        generator knob's corpus, target and guidance)."""
        entry = self.knob_config.get(knob) or {}
        options = {
            "bootstrap": knob_bootstrap(KNOBS[knob], entry, self.config),
            "seed": int(self.config["probes"]["seeds"][0]),
            "metrics": knob_metrics(KNOBS[knob], self.config),
        }
        if KNOBS[knob].reads == "generate":
            corpus, target, guidance = generate_subject(self.stages, knob, self.knob_config)
            options |= {"corpus": corpus, "target": target, "guidance": guidance}
        return options

    def knob_inputs(self, wildcards: Any) -> dict[str, list[str]]:
        """The edges and benchmark files a knob's points read (each once)."""
        plan = self.setting_plan(wildcards.knob)
        files = [
            p
            for run in plan
            for role in ("edges", "tables")
            for paths in run[role].values()
            for p in paths
        ]
        return {
            "edges": list(dict.fromkeys(files)),
            "benchmarks": list(dict.fromkeys(b for run in plan for b in run["benchmarks"])),
        }


def write_source(folder: str | os.PathLike[str], text: str) -> str:
    """The absolute path of a file in `folder` holding `text`, named by its content's hash:
    written (whole, by a rename) only where no such file is, so an unchanged text keeps its
    file and mtime, and runs parsing other texts in the same folder never overwrite it."""
    target = Path(folder).absolute() / f"{hashlib.sha256(text.encode()).hexdigest()[:16]}.smk"
    if not target.exists():
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(f"{target.name}.{uuid.uuid4().hex}.tmp")
        tmp.write_text(text)
        os.replace(tmp, target)
    return str(target)
