"""The regime's plan (where generated touch helps): its natural corpora, cells and generators'
edges (rules/regime.smk)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from tacgen_lib.corpus.splits import split_size
from tacgen_lib.generate.regime_sets import PAIRINGS, check_regime_sizes, regime_corpora

REGIME_DIR = "results/generate/regime"
REGIME_CELL = f"{REGIME_DIR}/{{corpus}}/seed~{{seed}}"
REGIME_REPORT = "results/report/regime"
#: the positive control's rows of one cell (rule regime_look_control, `generate.look_control`)
REGIME_CONTROL = f"{REGIME_CELL}/look_control.parquet"
#: the regime page's items and their kinds
REGIME_ITEMS = {
    "findings": "html",
    "table": "html",
    "ladder": "html",
    "heatmap": "png",
    "curves": "png",
    "pool": "html",
    "pool_curve": "png",
}


@dataclass(frozen=True)
class RegimePlan:
    """config regime (None: no regime, as in a config given with --replace-workflow-config),
    its sizes checked against each natural corpus and its test split."""

    settings: Mapping[str, Any] | None

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> RegimePlan:
        plan = cls(config.get("regime"))
        by_scale = config["splits"]["by_scale"]
        for corpus in plan.corpora:
            if corpus in by_scale:
                raise ValueError(
                    f"config splits.by_scale: corpus {corpus!r} is the regime's; it needs the "
                    "random split"
                )
            n = int(config["corpora"][corpus]["n"])
            check_regime_sizes(
                corpus,
                n,
                # the corpus's test split as make_splits draws it
                split_size(n, config["splits"]["fractions"].get("test", 0.0)),
                plan.settings["n_labelled"],
                plan.settings["n_pool"],
            )
        return plan

    @cached_property
    def corpora(self) -> list[str]:
        """Its natural corpora, one per rho (joined to the corpora by validate_config)."""
        return list(regime_corpora(self.settings))

    @cached_property
    def seeds(self) -> list[Any]:
        return self.settings["seeds"] if self.settings else []

    @cached_property
    def generator_cells(self) -> list[tuple[int, str]]:
        """Every (pool size, pairing) generator of a corpus x seed, in the order of its
        outputs."""
        return (
            [(int(n), p) for n in self.settings["n_pool"] for p in PAIRINGS]
            if self.settings
            else []
        )

    @cached_property
    def control_corpora(self) -> list[str]:
        """The corpus the positive control of the curve against the pool size runs on
        (`generate.look_control`): the largest rho's, where config regime.look_control_snr is
        set, regime.n_pool has two or more sizes (a curve) and that rho is above 0 (its look
        says something of the material); else none."""
        s = self.settings
        if not self.corpora or s.get("look_control_snr") is None or len(s["n_pool"]) < 2:
            return []
        rho, corpus = max((float(r), c) for c, r in zip(self.corpora, s["rhos"], strict=True))
        return [corpus] if rho > 0 else []

    def control_files(self, path: str) -> list[str]:
        """`path` (with {corpus} and {seed}) of every positive-control cell."""
        return [path.format(corpus=c, seed=s) for c in self.control_corpora for s in self.seeds]

    def cells(self) -> list[tuple[str, str]]:
        """Every (corpus, seed text) cell."""
        return [(c, str(s)) for c in self.corpora for s in self.seeds]

    def files(self, path: str) -> list[str]:
        """`path` (with {corpus} and {seed}) of every cell."""
        return [path.format(corpus=c, seed=s) for c, s in self.cells()]

    def t_gen(self, corpus: str, seed: str) -> list[str]:
        """The generated touch of every generator of one cell."""
        return [
            f"{REGIME_CELL}/pool~{n}/{p}/t_gen.parquet".format(corpus=corpus, seed=seed)
            for n, p in self.generator_cells
        ]
