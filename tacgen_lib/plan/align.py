"""The align stage's plan: its grid of cells (corpora x variants x seeds x taus x N), the
canonical cell paths, and the aligned projections other stages ask for (rules/align.smk)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from snakemake.io import expand

from tacgen_lib.align.cell_names import CELL_PATTERN, cell_name, tau_text

#: a grid cell's folder
ALIGN_CELL = f"results/align/{CELL_PATTERN}"
ALIGN_REPORT = "results/report/align"


@dataclass(frozen=True)
class AlignPlan:
    """config align, the corpora whose heads may be trained, and the probes' heads cell."""

    settings: Mapping[str, Any]
    #: the grid's corpora and the transfer corpus (its heads, at the probes' heads cell, are
    #: the transfer stage's upper reference)
    heads_corpora: list[str]
    probes_heads: Mapping[str, Any]

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> AlignPlan:
        align = config["align"]
        transfer = config["transfer"].get("corpus")
        extra = [transfer] if transfer and transfer not in align["corpora"] else []
        return cls(align, align["corpora"] + extra, config["probes"]["heads"])

    @cached_property
    def corpora(self) -> list[str]:
        return self.settings["corpora"]

    def grid(self, path: str) -> list[str]:
        """`path` expanded over every grid cell (corpora x variants x seeds x taus x N)."""
        return expand(
            path,
            corpus=self.corpora,
            variant=self.settings["variants"],
            seed=self.settings["seeds"],
            tau=[tau_text(t) for t in self.settings["taus"]],
            n_train=[str(n) for n in self.settings["n_train"]],
        )

    def cells(self) -> list[str]:
        """Names of every grid cell, in the order `grid` expands them."""
        return self.grid(CELL_PATTERN)

    def aligned_edge(
        self, heads_from: str, target: str, variant: str, seed: Any, tau: Any, n_train: Any
    ) -> str:
        """Aligned projections of corpus `target` by the heads trained on `heads_from` (one
        cell)."""
        if heads_from not in self.heads_corpora:
            raise ValueError(
                f"aligned_edge: heads_from={heads_from!r} is not in align.corpora "
                f"{self.corpora}; add it there so its heads are trained"
            )
        cell = cell_name(heads_from, variant, seed, tau, n_train)
        return f"results/align/{cell}/aligned~{target}.parquet"

    def heads_cell_edge(self, heads_from: str, target: str, seed: Any) -> str:
        """`aligned_edge` at the probes' heads cell (config probes.heads)."""
        return self.heads_cell_edge_at(heads_from, target, seed, self.probes_heads["n_train"])

    def heads_cell_edge_at(self, heads_from: str, target: str, seed: Any, n_train: Any) -> str:
        """`aligned_edge` at the probes' heads variant and τ, with heads trained on `n_train`
        rows."""
        heads = self.probes_heads
        return self.aligned_edge(heads_from, target, heads["variant"], seed, heads["tau"], n_train)

    def reference_n(self) -> str:
        """Training size of the τ table and the curve figure: 'all' if in the grid, else the
        largest."""
        ns = [str(n) for n in self.settings["n_train"]]
        return "all" if "all" in ns else max(ns, key=int)

    def reference_tau(self) -> str:
        """τ of the N-scaling table: the probes' heads τ if in the grid, else the first τ."""
        taus = [tau_text(t) for t in self.settings["taus"]]
        want = tau_text(self.probes_heads["tau"])
        return want if want in taus else taus[0]
