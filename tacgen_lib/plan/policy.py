"""The policy stage's plan: its cells, episode shards, the alignment heads it palpates with,
its rollouts and benchmark files (rules/policy.smk)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from tacgen_lib.align.cell_names import cell_name as align_cell_name
from tacgen_lib.plan.paths import benchmark_file
from tacgen_lib.policy.policy_cells import CELL_PATTERN, REFERENCES, all_cells
from tacgen_lib.policy.policy_cells import cell_name as policy_cell_name
from tacgen_lib.policy.settings import PolicySettings

POLICY_DIR = "results/policy"
POLICY_REPORT = "results/report/policy"
POLICY_TABLES = ["success", "sweep", "regression"]
POLICY_FIGURES = ["sweep", "failures", "filmstrip"]


@dataclass(frozen=True)
class PolicyPlan:
    """config policy (its settings) and the alignment seeds whose heads it reads."""

    settings: PolicySettings
    align_seeds: list[Any]
    #: whether the stage runs: it needs the heads of a simulated paired corpus, so a config
    #: without that corpus (real data only) leaves the policy stage out of `all`
    on: bool

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> PolicyPlan:
        s = PolicySettings.from_config(config["policy"])
        align = config["align"]
        on = s.heads_from in config["corpora"]
        if on and s.heads_from not in align["corpora"]:
            raise ValueError(
                f"config policy.heads_from: {s.heads_from!r} is not in align.corpora "
                f"{align['corpora']}; the palpation features need its alignment heads"
            )
        if on and s.heads_seed not in align["seeds"]:
            raise ValueError(
                f"config policy.heads_seed: {s.heads_seed} is not in align.seeds {align['seeds']}"
            )
        return cls(s, align["seeds"], on)

    @cached_property
    def cells(self) -> list[str]:
        """Every cell's name (condition x hidden x epochs x seed)."""
        return [policy_cell_name(c) for c in all_cells(self.settings)]

    @cached_property
    def shards(self) -> dict[str, int]:
        """Per episode set, its shards."""
        return {
            "demos": self.settings.collect_shards,
            "heldout": self.settings.collect_shards,
        }

    def episodes(self, episode_set: str | None = None) -> list[str]:
        """The episode shards of one set (of both where None)."""
        sets = [episode_set] if episode_set else sorted(self.shards)
        return [
            f"{POLICY_DIR}/episodes/{s}/shard~{k}.parquet"
            for s in sets
            for k in range(self.shards[s])
        ]

    def heads(self) -> dict[str, str]:
        """The alignment heads of every alignment seed (the BC uses heads_seed's)."""
        s = self.settings
        cells = {
            seed: align_cell_name(s.heads_from, s.heads_variant, seed, s.heads_tau, s.heads_n_train)
            for seed in self.align_seeds
        }
        return {str(seed): f"results/align/{cell}/heads.pt" for seed, cell in cells.items()}

    def rollouts(self, pattern: str = "{d}/rollouts/{cell}/shard~{k}.parquet") -> list[str]:
        """`pattern` of every cell's every rollout shard."""
        return [
            pattern.format(d=POLICY_DIR, cell=c, k=k)
            for c in self.cells
            for k in range(self.settings.rollout_shards)
        ]

    def train_benchmarks(self) -> list[str]:
        """The benchmark files of every learned cell's training job (the references train
        none)."""
        return [
            benchmark_file("train_policy", policy_cell_name(c))
            for c in all_cells(self.settings)
            if c[0] not in REFERENCES
        ]

    def weights(self, wildcards: Any) -> list[str]:
        """A cell's trained policy (none for the references)."""
        if wildcards.condition in REFERENCES:
            return []
        return [f"{POLICY_DIR}/policies/{CELL_PATTERN}/policy.pt"]
