"""The transfer stage's plan: the second sensor's corpus, its heads views and their aligned
edges (rules/transfer.smk)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from tacgen_lib.plan.align import AlignPlan

TRANSFER_REPORT = "results/report/transfer"


@dataclass(frozen=True)
class TransferPlan:
    """config transfer, checked: its corpus split by object, its views' heads trained."""

    settings: Mapping[str, Any]
    #: heads view -> corpus whose heads project the transfer corpus (empty: no stage)
    views: dict[str, str]
    align: AlignPlan

    @classmethod
    def from_config(cls, config: Mapping[str, Any], align: AlignPlan) -> TransferPlan:
        transfer = config["transfer"]
        corpus = transfer.get("corpus")
        if not corpus:
            return cls(transfer, {}, align)
        where = f"config transfer.corpus = {corpus!r}"
        if corpus not in config["corpora"]:
            raise ValueError(f"{where}: not a corpus (have {sorted(config['corpora'])})")
        if corpus not in config["splits"]["by_object"]:
            raise ValueError(
                f"{where}: the corpus must be split by object (config splits.by_object), so no "
                "object is both fitted and tested"
            )
        for key in ("source", "floor"):
            if transfer[key] not in align.corpora:
                raise ValueError(
                    f"config transfer.{key} = {transfer[key]!r} is not in align.corpora "
                    f"{align.corpora}: its heads are not trained"
                )
        views = {"source": transfer["source"], "target": corpus, "floor": transfer["floor"]}
        return cls(transfer, views, align)

    @cached_property
    def corpus(self) -> str | None:
        """The second sensor's corpus, None for no stage."""
        return self.settings.get("corpus")

    def aligned(self, view: str, seed: Any) -> str:
        """The transfer corpus's aligned projections by one view's heads (the probes' heads
        cell, alignment seed `seed`; the transfer corpus's own heads on all of its train
        rows)."""
        heads_from = self.views[view]
        if heads_from == self.corpus:
            return self.align.heads_cell_edge_at(heads_from, self.corpus, seed, "all")
        return self.align.heads_cell_edge(heads_from, self.corpus, seed)
