"""PolicySettings: the one settings object of the policy stage (config `policy:`)."""

from __future__ import annotations

from dataclasses import dataclass

from tacgen_lib.io.schema import SchemaSettings, schema_fields

__all__ = ["PolicySettings", "CONDITIONS", "LEARNED_CONDITIONS"]

#: Learned behaviour-cloning conditions (matched capacity), and every summary condition.
LEARNED_CONDITIONS = ("v", "vt_aligned", "vt_raw", "vt_null")
CONDITIONS = ("oracle", "vision_ceiling", *LEARNED_CONDITIONS)

_PAIRS = ("size_range", "density_range", "friction_range", "stiffness_range")


@dataclass(frozen=True)
@schema_fields("policy")
class PolicySettings(SchemaSettings):
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
        """The schema's bounds (`SchemaSettings`), then the rules between keys."""
        super().__post_init__()
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
