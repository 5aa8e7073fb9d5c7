"""The generate stage's plan: its generators (corpus x seed), their sampling cells, the report's
reference cell, and the probes no generator changes (rules/generate.smk)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from tacgen_lib.generate.sampling_cells import SAMPLE_CELL, guidance_text, sample_cells
from tacgen_lib.generate.settings import baseline_targets, check_grid, generate_grids
from tacgen_lib.plan.paths import benchmark_file, feature_edge

GENERATE_REPORT = "results/report/generate"
#: the generate page's items and their kinds
GENERATE_ITEMS = {
    "headline": "html",
    "honesty": "html",
    "family": "html",
    "protocol": "html",
    "fidelity": "html",
    "heatmap": "png",
    "steps": "png",
    "pca": "png",
    "permutation": "png",
    "curves": "png",
}
#: One sampling cell's seconds, timed by its generator's sampling job (benchmark format)
SAMPLE_SECONDS = benchmark_file("sample_generator", "{corpus}/{seed}_{sampler}_{guidance}_{steps}")


@dataclass(frozen=True)
class GeneratePlan:
    """config generate, checked against the corpora, with the targets of the probes no
    generator changes (rule fit_generator_baselines)."""

    settings: Mapping[str, Any]
    #: per corpus, the targets of the probes no generator changes: the latent generator's
    #: corpora and the pixel generators' judged ones (`generate.settings.baseline_targets`)
    baseline_targets: dict[str, dict[str, Any]]

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> GeneratePlan:
        generate = config["generate"]
        check_grid(generate["samplers"], generate["train_steps"])
        for corpus in generate["corpora"]:
            if corpus not in config["corpora"]:
                raise ValueError(
                    f"config generate.corpora: {corpus!r} is not a corpus "
                    f"(have {sorted(config['corpora'])})"
                )
        return cls(generate, baseline_targets(config))

    @cached_property
    def corpora(self) -> list[str]:
        """The generators' corpora in config order: the first feeds the PCA figure."""
        return list(self.settings["corpora"])

    @cached_property
    def grids(self) -> dict[str, Any]:
        """The C and lambda grids of every probe that judges generated touch."""
        return generate_grids(self.settings)

    @cached_property
    def cells(self) -> list[tuple[str, str, str]]:
        """Every sampling cell (sampler, guidance text, steps text) of one generator."""
        return sample_cells(self.settings["guidance"], self.settings["samplers"])

    def reference(self) -> dict[str, Any]:
        """The report's reference cell: first sampler, its most steps, w = 1 if in the grid."""
        sampler = next(iter(self.settings["samplers"]))
        ws = [guidance_text(w) for w in self.settings["guidance"]]
        return {
            "sampler": sampler,
            "steps": max(int(s) for s in self.settings["samplers"][sampler]),
            "guidance": "1" if "1" in ws else ws[0],
        }

    def reference_cell(self) -> tuple[str, str, str]:
        """The reference cell as (sampler, guidance text, steps text), one of `cells`."""
        ref = self.reference()
        return (ref["sampler"], ref["guidance"], str(ref["steps"]))

    def generators(self) -> list[tuple[str, str]]:
        """Every generator: (corpus, seed text)."""
        return [(c, str(s)) for c in self.corpora for s in self.settings["seeds"]]

    def generator_files(self, path: str) -> list[str]:
        """`path` (with {corpus} and {seed}) of every generator."""
        return [path.format(corpus=c, seed=s) for c, s in self.generators()]

    def all_sample_cells(self) -> list[tuple[str, ...]]:
        """Every generator's every sampling cell: (corpus, seed, sampler, guidance, steps)."""
        return [(c, s, *cell) for c, s in self.generators() for cell in self.cells]

    def tactile(self, corpus: str) -> str:
        """The tactile feature edge the generators learn and are judged on."""
        return feature_edge(corpus, "tactile", self.settings["variant"])


def sample_edge(corpus: str, seed: Any, sampler: str, guidance: str, steps: Any) -> str:
    """The generated touch of one sampling cell."""
    return f"{SAMPLE_CELL}/t_gen.parquet".format(
        corpus=corpus, seed=seed, sampler=sampler, guidance=guidance, steps=steps
    )


def sample_benchmark(corpus: str, seed: Any, sampler: str, guidance: str, steps: Any) -> str:
    """One sampling cell's seconds (`SAMPLE_SECONDS`)."""
    return SAMPLE_SECONDS.format(
        corpus=corpus, seed=seed, sampler=sampler, guidance=guidance, steps=steps
    )
