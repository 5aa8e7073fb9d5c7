"""What the generator stages' jobs read of their inputs, the same way in every script: the
generator targets' probes (`job_target_specs`) and the inputs every judge of generated touch
shares (`GeneratorJob`: rules evaluate_generator and evaluate_pixel_generators)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from tacgen_lib.corpus.splits import assert_trainable, ids_in_split
from tacgen_lib.generate.baselines import Baselines, TargetSpec, baselines_from_frame, target_specs
from tacgen_lib.io import edges

__all__ = ["GeneratorJob", "job_target_specs"]


def job_target_specs(job: Any, splits: pd.DataFrame, *, cv_repeats: int) -> list[TargetSpec]:
    """`target_specs` of Snakemake job `job`: the corpus of its wildcards, its input
    ``manifest``, its params ``targets``, ``corpus`` (the declaration), ``probes``,
    ``probe_seed`` and ``grids`` (the probes' C and lambda grids, `settings.generate_grids`), and its
    rule (named in a leak's error)."""
    return target_specs(
        edges.read(job.input.manifest).frame,
        splits,
        corpus=job.wildcards.corpus,
        targets=job.params.targets,
        corpus_config=job.params.corpus,
        probes_config=job.params.probes,
        probe_seed=job.params.probe_seed,
        rule=job.rule,
        cv_repeats=cv_repeats,
        grids=job.params.grids,
    )


@dataclass(frozen=True)
class GeneratorJob:
    """The inputs a judge of one corpus x generator seed's generated touch shares with every
    other: the `splits`, the `targets`' probes, their fitted `baselines` (V, V + T_real,
    nonlinear V), V and real T by sample_id, and the rows the generator learnt from
    (`generator_train_ids`, the corpus's train rows, which a ridge V->T generator learns
    from too)."""

    corpus: str
    seed: int
    splits: pd.DataFrame
    targets: list[TargetSpec]
    baselines: dict[str, Baselines]
    vision: dict[str, np.ndarray]
    t_real: dict[str, np.ndarray]
    generator_train_ids: list

    @classmethod
    def read(cls, job: Any, *, cv_repeats: int) -> GeneratorJob:
        """From Snakemake job `job` (wildcards ``corpus`` and ``seed``; inputs ``splits``,
        ``manifest``, ``baselines``, ``v`` and ``t``; the params of `job_target_specs`)."""
        corpus = job.wildcards.corpus
        splits = edges.read(job.input.splits).frame
        train_ids = sorted(ids_in_split(splits, "train", corpus))
        assert_trainable(train_ids, splits, rule=job.rule, allowed=("train",))
        targets = job_target_specs(job, splits, cv_repeats=cv_repeats)
        baselines = baselines_from_frame(
            edges.read(job.input.baselines).frame, targets, source=job.input.baselines
        )
        return cls(
            corpus=corpus,
            seed=int(job.wildcards.seed),
            splits=splits,
            targets=targets,
            baselines=baselines,
            vision=edges.read_vector_map(job.input.v, "vit"),
            t_real=edges.read_vector_map(job.input.t, "vit"),
            generator_train_ids=train_ids,
        )

    def keywords(self) -> dict[str, Any]:
        """The keyword arguments `evaluate.evaluate_generator` and `utility.evaluate_arms`
        share: corpus, seed, vision, t_real, baselines, generator_train_ids."""
        return {
            "corpus": self.corpus,
            "seed": self.seed,
            "vision": self.vision,
            "t_real": self.t_real,
            "baselines": self.baselines,
            "generator_train_ids": self.generator_train_ids,
        }
