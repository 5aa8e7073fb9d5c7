"""The features stage's plan: the backbones' frames, the extraction jobs' threads and priority,
and the feature edges every corpus gets (rules/features.smk)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from tacgen_lib.features.families import BackboneSpec
from tacgen_lib.features.settings import pretraining_corpora
from tacgen_lib.generate.regime_sets import regime_corpora
from tacgen_lib.plan.paths import corpus_edge, feature_edge, preprocessed_frames
from tacgen_lib.plan.priorities import CHAIN_PRIORITY

#: the two modalities, each with its own backbone
MODALITIES = ["vision", "tactile"]
#: what V decodes of each simulated corpus's looks (rule visibility_check)
VISIBILITY_EDGE = "results/features/visibility.parquet"
#: the visibility page's items and their kinds
VISIBILITY_ITEMS = {"table": "html", "figure": "png"}


@dataclass(frozen=True)
class FeaturesPlan:
    """config features, with the regime's natural corpora (whose extraction jobs run one
    thread at a lower priority) and the preprocessing variants."""

    settings: Mapping[str, Any]
    natural_grid: Sequence[str]

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> FeaturesPlan:
        return cls(config["features"], list(regime_corpora(config.get("regime"))))

    @cached_property
    def pretrain(self) -> Mapping[str, Any]:
        return self.settings["pretrain"]

    @cached_property
    def pretraining_corpora(self) -> list[str]:
        return list(pretraining_corpora(self.pretrain))

    def backbone(self, modality: str) -> BackboneSpec:
        """The backbone of a modality (config features.backbones)."""
        return BackboneSpec.from_config(self.settings["backbones"][modality])

    def extraction_threads(self, wildcards: Any) -> int:
        """An extraction job's threads: config features.threads, but one for the regime's
        natural corpora. Their features feed only the regime's jobs, which run last, never the
        policy chain; one thread keeps its core busy, and a one-thread job can run beside a long
        one-thread job where a two-thread job waits for both cores."""
        return 1 if wildcards.corpus in self.natural_grid else self.settings["threads"]

    def extraction_priority(self, wildcards: Any) -> int:
        """The policy chain's priority (CHAIN_PRIORITY), except for the regime's natural corpora."""
        return 0 if wildcards.corpus in self.natural_grid else CHAIN_PRIORITY

    def backbone_frames(self, modality: str, corpus: str) -> str:
        """The frames a modality's backbone sees: RGB from the corpus edge, tactile frames of
        the pretraining variant."""
        if modality == "vision":
            return corpus_edge(corpus)
        return preprocessed_frames(corpus, self.pretrain["variant"])

    def pretraining_frames(self, modality: str, spec: BackboneSpec | None = None) -> list[str]:
        """The frame edges a backbone of `modality` (`spec`; the main one where None) learns
        from: each corpus of features.pretrain.corpus; none for a checkpoint or the random
        init, which read no frames and so wait for no corpus."""
        spec = spec or self.backbone(modality)
        if not spec.pretrains(int(self.pretrain["epochs"])):
            return []
        return [self.backbone_frames(modality, c) for c in self.pretraining_corpora]

    def corpus_feature_edges(self, config: Mapping[str, Any]) -> list[str]:
        """Every corpus's feature edges: vision, and tactile per preprocessing variant, but
        only the generator's variant for a corpus only the regime reads (its natural corpora)
        and only the heads' variant for the transfer corpus (config probes.heads). A
        pretraining corpus's frames are the input of pretrain_backbone, which Snakemake makes
        on demand: no target needed."""
        regime_only = (
            set(self.natural_grid)
            - set(config["align"]["corpora"])
            - set(config["generate"]["corpora"])
            - {f["corpus"] for f in config["probes"]["families"].values()}
            - {self.settings["pretrained_vs_random"]["corpus"]}
        )
        one_variant = {c: config["generate"]["variant"] for c in regime_only}
        transfer = config["transfer"].get("corpus")
        if transfer:
            one_variant[transfer] = config["probes"]["heads"]["variant"]
        edges = []
        for corpus in sorted(config["corpora"]):
            edges.append(feature_edge(corpus, "vision"))
            variants = (
                [one_variant[corpus]] if corpus in one_variant else config["preprocess"]["variants"]
            )
            edges += [feature_edge(corpus, "tactile", v) for v in variants]
        return edges
