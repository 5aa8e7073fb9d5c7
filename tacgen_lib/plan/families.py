"""The backbone families' plan (tacgen_lib.features.families): which families get their own
backbones, which are the main DAG's, the paths the rules of rules/backbones.smk read."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from tacgen_lib.features.families import (
    BackboneSpec,
    FamilySettings,
    check_backbone,
    check_checkpoint_file,
)
from tacgen_lib.plan.features import MODALITIES, FeaturesPlan
from tacgen_lib.plan.paths import corpus_edge, feature_edge, preprocessed_frames

FAMILY_PROBE = "results/backbones/{family}/probes.parquet"


@dataclass(frozen=True)
class FamiliesPlan:
    """config backbones against the main DAG's backbones and the probe jobs it runs; every
    backbone's settings checked and its checkpoint present before any job runs."""

    settings: FamilySettings
    features: FeaturesPlan
    #: the tactile frames the probes read (config probes.heads.variant)
    variant: str
    #: the corpora of the probe families the families are judged on
    corpora: list[str]
    #: the probes stage's (family, protocol) jobs
    probe_jobs: list[tuple[str, str]]

    @classmethod
    def from_config(
        cls, config: Mapping[str, Any], features: FeaturesPlan, probe_jobs: list[tuple[str, str]]
    ) -> FamiliesPlan:
        feat = features.settings
        for m in MODALITIES:
            where = f"features.backbones.{m}"
            check_backbone(
                BackboneSpec.from_config(feat["backbones"][m], where),
                where=where,
                dino_epochs=int(feat["pretrain"]["epochs"]),
                mae_epochs=int(feat["mae"]["epochs"]),
                features_pool=feat["pool"],
            )
            # an official checkpoint must be here before any job runs (relative to the
            # working directory, where results/ lives)
            check_checkpoint_file(BackboneSpec.from_config(feat["backbones"][m]), where=where)
        families = FamilySettings.from_config(config)
        for f in families.run:
            for m in MODALITIES:
                check_checkpoint_file(families.families[f][m], where=f"backbones.families.{f}.{m}")
        probes = config["probes"]
        corpora = sorted({probes["families"][p]["corpus"] for p in families.probes})
        return cls(families, features, probes["heads"]["variant"], corpora, probe_jobs)

    @cached_property
    def own(self) -> list[str]:
        """The families run with their own backbones (not the main DAG's)."""
        return self.settings.own(self.features.settings)

    @cached_property
    def main(self) -> list[str]:
        """The main DAG's family, where it is run (at most one)."""
        return [f for f in self.settings.run if f not in self.own]

    @cached_property
    def jobs(self) -> list[tuple[str, str]]:
        """The (probe family, protocol) jobs a family is judged on."""
        return [(p, q) for p in self.settings.probes for q in self.settings.protocols]

    @cached_property
    def main_from_probes(self) -> list[str]:
        """The main family where its rows are the probes stage's own headline rows (that stage
        probes every job asked here: nothing is computed twice)."""
        return [f for f in self.main if all(j in self.probe_jobs for j in self.jobs)]

    @cached_property
    def computed(self) -> list[str]:
        """The families whose probe rows family_probe computes."""
        return [f for f in self.settings.run if f not in self.main_from_probes]

    @cached_property
    def on(self) -> bool:
        """Whether the stage runs: families to compare and probe families to judge them on."""
        return bool(self.settings.run and self.settings.probes)

    @cached_property
    def on_findings(self) -> bool:
        """Whether the findings page has backbone rows: some family is not the main one."""
        return bool(self.settings.probes) and bool(self.own)

    def spec(self, family: str, modality: str) -> BackboneSpec:
        return self.settings.families[family][modality]

    def labels(self, family: str) -> dict[str, str]:
        """What the report says of a family's two backbones."""
        epochs = int(self.features.pretrain["epochs"])
        return {m: self.spec(family, m).label(epochs) for m in MODALITIES}

    def features_edge(self, family: str, corpus: str, modality: str) -> str:
        """A family's feature edge of a corpus (the main edge for the main family)."""
        if family not in self.own:
            return feature_edge(corpus, modality, self.variant)
        return f"results/features/families/{family}/{corpus}/{modality}.parquet"

    def frames(self, modality: str) -> list[str]:
        """The frames a family's backbone of `modality` is extracted on, per probe corpus."""
        if modality == "vision":
            return [corpus_edge(c) for c in self.corpora]
        return [preprocessed_frames(c, self.variant) for c in self.corpora]

    def edges(self) -> list[str]:
        """The stage's hashed edges: the summary, the computed families' rows, and the own
        families' backbones and features."""
        edges = ["results/backbones/summary.parquet"]
        edges += [FAMILY_PROBE.format(family=f) for f in self.computed]
        for f in self.own:
            edges += [f"results/features/families/{f}/{m}.pt" for m in MODALITIES]
            edges += [
                f"results/features/families/{f}/{c}/{m}.parquet"
                for c in self.corpora
                for m in MODALITIES
            ]
        return edges
