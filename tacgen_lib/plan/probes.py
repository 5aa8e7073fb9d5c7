"""The probes stage's plan: its families and (family, protocol) jobs, the edges one family
reads, and the report's items (rules/probes.smk)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from tacgen_lib.plan.align import AlignPlan
from tacgen_lib.plan.paths import feature_edge
from tacgen_lib.probes.settings import RobustnessSettings, check_families, has_aligned_rows

PROBE_DIR = "results/probes/{family}/protocol~{protocol}"
PROBE_REPORT = "results/report/probes"
PROBE_TABLES = [
    "controlled",
    "paired",
    "sweep",
    "align_seeds",
    "variants",
    "controls",
    "fusions",
]
PROBE_FIGURES = ["forest", "confusion"]
ROBUSTNESS_TABLES = ["robustness", "multiplicity", "within_scale", "training_size"]
#: the edges every probe job writes
PROBE_EDGES = ["seed~{seed}", "sweep~{seed}", "confusion~{seed}"]


@dataclass(frozen=True)
class ProbesPlan:
    """config probes (its families checked: no family repeats another's rows), the
    preprocessing variants and the alignment plan whose heads the families read."""

    settings: Mapping[str, Any]
    variants: list[str]
    align: AlignPlan

    @classmethod
    def from_config(cls, config: Mapping[str, Any], align: AlignPlan) -> ProbesPlan:
        check_families(config["probes"]["families"])
        return cls(config["probes"], config["preprocess"]["variants"], align)

    @cached_property
    def families(self) -> list[str]:
        return sorted(self.settings["families"])

    @cached_property
    def robustness(self) -> RobustnessSettings:
        """Every family under raw, the robustness families under each other protocol variant
        (not where it equals raw)."""
        return RobustnessSettings.from_config(
            self.settings["robustness"], self.settings["families"]
        )

    @cached_property
    def jobs(self) -> list[tuple[str, str]]:
        """The (family, protocol) jobs."""
        return self.robustness.jobs(self.settings["families"])

    def job_edges(self, edge: str) -> list[str]:
        """`edge` ("seed~{seed}", ...) of every probe job: (family, protocol) x probe seed."""
        return [
            f"{PROBE_DIR}/{edge}.parquet".format(family=f, protocol=p, seed=s)
            for f, p in self.jobs
            for s in self.settings["seeds"]
        ]

    def family(self, family: str) -> dict[str, Any]:
        """A family's declaration, with its name."""
        return {"name": family, **self.settings["families"][family]}

    def align_seeds(self, family: str) -> list[Any]:
        """Alignment seeds whose aligned projections a family probes (none for pixel-V
        families)."""
        return (
            self.align.settings["seeds"] if has_aligned_rows(self.family(family)["vision"]) else []
        )

    def inputs(self, wildcards: Any) -> dict[str, Any]:
        """Edges one probe family reads: labels, splits, raw V/T features, aligned
        projections."""
        fam = self.family(wildcards.family)
        return {
            **self.raw_inputs(wildcards),
            "aligned": [
                self.align.heads_cell_edge(fam["heads_from"], fam["corpus"], seed)
                for seed in self.align_seeds(wildcards.family)
            ],
        }

    def raw_inputs(self, wildcards: Any) -> dict[str, Any]:
        """`inputs` without the aligned projections (the raw-feature robustness rules)."""
        fam = self.family(wildcards.family)
        return {
            "manifest": "results/corpus/manifest.parquet",
            "splits": "results/corpus/splits.parquet",
            "vision": feature_edge(fam["corpus"], "vision"),
            "tactile": [feature_edge(fam["corpus"], "tactile", v) for v in self.variants],
        }
