"""PolicySettings: the one settings object of the policy stage (config `policy:`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from tacgen_lib.io.config import settings_from
from tacgen_lib.io.schema import check_settings, setting

__all__ = ["PolicySettings", "CONDITIONS", "LEARNED_CONDITIONS"]

#: Learned behaviour-cloning conditions (matched capacity), and every summary condition.
LEARNED_CONDITIONS = ("v", "vt_aligned", "vt_raw", "vt_null")
CONDITIONS = ("oracle", "vision_ceiling", *LEARNED_CONDITIONS)

_PAIRS = ("size_range", "density_range", "friction_range", "stiffness_range")


@dataclass(frozen=True)
class PolicySettings:
    """Every knob of the policy stage; lengths m, forces N, times s.

    Task: object ranges (size visible; density, friction, stiffness invisible), crush depth
    (crush_limit = stiffness x crush_depth), lift/hold profile, slip limit, holding contact
    model (impratio, noslip_iterations), timestep. Palpation: the two squeeze forces, the heft.
    Data: seed, demonstrations, held-out episodes, shards. Features: the alignment cell
    (heads_variant, heads_tau, heads_n_train, heads_seed for the BC; every alignment seed for the
    regression). Learning: MLP (hidden, layers, epochs, seeds, lr, batch), the V-only capacity
    sweep, bootstrap resamples, ceiling Monte Carlo draws and force grid.

    The paper's BC recipe (lr 1e-4, 60 epochs, batch 128) is for 96 *trajectories* of many
    steps; here a demonstration is one (observation, grip force) pair, so 96 demos make one
    batch: the default trains longer (200 epochs of batch 32 at lr 1e-3).
    """

    seed: int = setting("policy.seed")
    n_demos: int = setting("policy.n_demos")
    n_heldout: int = setting("policy.n_heldout")
    collect_shards: int = setting("policy.collect_shards")
    rollout_shards: int = setting("policy.rollout_shards")
    timestep: float = setting("policy.timestep")
    size_range: tuple[float, float] = setting("policy.size_range")
    density_range: tuple[float, float] = setting("policy.density_range")
    friction_range: tuple[float, float] = setting("policy.friction_range")
    stiffness_range: tuple[float, float] = setting("policy.stiffness_range")
    crush_depth: float = setting("policy.crush_depth")
    min_window_ratio: float = setting("policy.min_window_ratio")
    max_window_ratio: float = setting("policy.max_window_ratio")
    close_time: float = setting("policy.close_time")
    lift_time: float = setting("policy.lift_time")
    hold_time: float = setting("policy.hold_time")
    lift_height: float = setting("policy.lift_height")
    slip_limit: float = setting("policy.slip_limit")
    impratio: float = setting("policy.impratio")
    noslip_iterations: int = setting("policy.noslip_iterations")
    finger_damping: float = setting("policy.finger_damping")
    palpation_forces: tuple[float, float] = setting("policy.palpation_forces")
    heft_height: float = setting("policy.heft_height")
    tactile_size: tuple[int, int] = setting("policy.tactile_size")
    image_size: tuple[int, int] = setting("policy.image_size")
    lift_effects: tuple[str, ...] = setting("policy.lift_effects")
    palpation_effects: tuple[str, ...] = setting("policy.palpation_effects")
    # the alignment cell whose heads project the palpation frames (one per alignment seed)
    heads_from: str = setting("policy.heads_from")
    heads_variant: str = setting("policy.heads_variant")
    heads_tau: float = setting("policy.heads_tau")
    heads_n_train: int | str = setting("policy.heads_n_train")
    heads_seed: int = setting("policy.heads_seed")
    hidden: int = setting("policy.hidden")
    layers: int = setting("policy.layers")
    epochs: int = setting("policy.epochs")
    lr: float = setting("policy.lr")
    weight_decay: float = setting("policy.weight_decay")
    batch_size: int = setting("policy.batch_size")
    seeds: tuple[int, ...] = setting("policy.seeds")
    sweep_hidden: tuple[int, ...] = setting("policy.sweep_hidden")
    sweep_epochs: tuple[int, ...] = setting("policy.sweep_epochs")
    sweep_seeds: tuple[int, ...] = setting("policy.sweep_seeds")
    bootstrap: int = setting("policy.bootstrap")
    ceiling_draws: int = setting("policy.ceiling_draws")
    force_grid: int = setting("policy.force_grid")

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | None) -> PolicySettings:
        """Build from config `policy:`; unknown keys and bad values are named."""
        return settings_from(cls, cfg, where="policy")

    @classmethod
    def tiny(cls) -> PolicySettings:
        return cls(
            n_demos=24,
            n_heldout=24,
            collect_shards=1,
            rollout_shards=1,
            hidden=64,
            epochs=30,
            lr=1e-3,
            batch_size=16,
            sweep_hidden=(32,),
            sweep_epochs=(30,),
            bootstrap=200,
            ceiling_draws=500,
            tactile_size=(32, 32),
            image_size=(32, 32),
        )

    def __post_init__(self) -> None:
        """The schema's bounds (`io.schema.check_settings`), then the rules between keys."""
        check_settings(self)
        for name in _PAIRS:
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise ValueError(f"config policy.{name}: need low <= high, got {[lo, hi]}")
        if not self.min_window_ratio <= self.max_window_ratio:
            raise ValueError(
                "config policy: need min_window_ratio <= max_window_ratio (a window must exist)"
            )
        lo_crush = self.stiffness_range[0] * self.crush_depth
        if max(self.palpation_forces) >= lo_crush:
            raise ValueError(
                f"config policy.palpation_forces: {max(self.palpation_forces)} N would crush the "
                f"softest object (crush limit {lo_crush:.2f} N); palpation must be harmless"
            )
