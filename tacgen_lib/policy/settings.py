"""PolicySettings: the one settings object of the policy stage (config `policy:`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from tacgen_lib.io.config import settings_from

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

    seed: int = 2024
    n_demos: int = 96
    n_heldout: int = 128
    collect_shards: int = 2
    rollout_shards: int = 1
    timestep: float = 0.001
    size_range: tuple[float, float] = (0.04, 0.06)
    density_range: tuple[float, float] = (150.0, 3000.0)
    friction_range: tuple[float, float] = (0.3, 1.0)
    stiffness_range: tuple[float, float] = (100.0, 5000.0)
    crush_depth: float = 0.004
    min_window_ratio: float = 1.6
    max_window_ratio: float = 3.0
    close_time: float = 0.2
    lift_time: float = 0.4
    hold_time: float = 0.6
    lift_height: float = 0.05
    slip_limit: float = 0.002
    impratio: float = 10.0
    noslip_iterations: int = 10
    finger_damping: float = 5.0
    palpation_forces: tuple[float, float] = (0.15, 0.35)
    heft_height: float = 0.004
    tactile_size: tuple[int, int] = (48, 48)
    image_size: tuple[int, int] = (64, 64)
    lift_effects: tuple[str, ...] = ("gravity", "contact_compliance", "friction_shear")
    palpation_effects: tuple[str, ...] = (
        "gravity",
        "contact_compliance",
        "friction_shear",
        "rgb",
        "texture",
        "tactile",
        "sensor_noise",
    )
    # the alignment cell whose heads project the palpation frames (one per alignment seed)
    heads_from: str = "sim_paired"
    heads_variant: str = "clip128"
    heads_tau: float = 0.07
    heads_n_train: str = "all"
    heads_seed: int = 42
    hidden: int = 512
    layers: int = 3
    epochs: int = 200
    lr: float = 1.0e-3
    weight_decay: float = 0.01
    batch_size: int = 32
    seeds: tuple[int, ...] = (42,)
    sweep_hidden: tuple[int, ...] = (128, 512)
    sweep_epochs: tuple[int, ...] = (200,)
    sweep_seeds: tuple[int, ...] = (42,)
    bootstrap: int = 5000
    ceiling_draws: int = 4000
    force_grid: int = 64

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | None) -> PolicySettings:
        """Build from config `policy:`; unknown keys and bad values are named."""
        out = settings_from(cls, cfg, where="policy")
        out.validate()
        return out

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

    def validate(self) -> None:
        for name in _PAIRS:
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                raise ValueError(f"config policy.{name}: need 0 < low <= high, got {[lo, hi]}")
        for name in (
            "n_demos",
            "n_heldout",
            "collect_shards",
            "rollout_shards",
            "hidden",
            "epochs",
        ):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"config policy.{name}: must be >= 1")
        if not 0 < self.timestep <= 0.005:
            raise ValueError(f"config policy.timestep: {self.timestep} not in (0, 0.005] s")
        if not 1 < self.min_window_ratio <= self.max_window_ratio:
            raise ValueError(
                "config policy: need 1 < min_window_ratio <= max_window_ratio (a window must exist)"
            )
        lo_crush = self.stiffness_range[0] * self.crush_depth
        if max(self.palpation_forces) >= lo_crush:
            raise ValueError(
                f"config policy.palpation_forces: {max(self.palpation_forces)} N would crush the "
                f"softest object (crush limit {lo_crush:.2f} N); palpation must be harmless"
            )
