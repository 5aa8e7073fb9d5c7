"""The features stage's settings: DINO pretraining from config ``features.pretrain``.

Every field that changes a pretrained backbone is a key of ``features.pretrain`` (the schema,
config/config.schema.yaml, gives the optional ones their defaults, which are these fields'
defaults), so a run can be reproduced from its config alone. ``corpus`` and ``variant`` (which
frames the backbone learns from) are read by the rules, not here. `DinoSettings.tiny()` is a
seconds-long run for tests.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

from tacgen_lib.io.config import settings_from

__all__ = ["DinoSettings", "MaeSettings", "backbones_pretrained"]


@dataclass(frozen=True)
class DinoSettings:
    """DINO self-distillation with DINOv2's safeguards; see `dino.pretrain_dino` for each term.

    epochs, batch_size, lr, seed: the run. Crops: `n_local_crops` local crops of `local_size`
    pixels (None: the multiple of 14 nearest 3/7 of the image size, at least 28). Head:
    `out_dim` prototypes behind a `hidden_dim` MLP with a `bottleneck_dim` bottleneck.
    Targets: `student_temp`, `teacher_temp` (warmed up linearly from `warmup_teacher_temp`
    over `warmup_teacher_temp_epochs`), `centering` ("sinkhorn_knopp" with
    `sinkhorn_iterations`, or "centre" with `center_momentum`). Regularisers: `koleo_weight`,
    `freeze_last_layer_epochs`. Optimiser: AdamW with `weight_decay`, `warmup_epochs` of lr
    warm-up, gradient clipping at `clip_grad`; teacher EMA from `momentum_teacher` to 1.
    Augmentation: colour `jitter` strength.
    """

    epochs: int = 8
    batch_size: int = 64
    lr: float = 5e-4
    seed: int = 0
    n_local_crops: int = 4
    local_size: int | None = None
    out_dim: int = 1024
    hidden_dim: int = 512
    bottleneck_dim: int = 128
    student_temp: float = 0.1
    teacher_temp: float = 0.04
    warmup_teacher_temp: float | None = None
    warmup_teacher_temp_epochs: int = 0
    centering: Literal["sinkhorn_knopp", "centre"] = "sinkhorn_knopp"
    sinkhorn_iterations: int = 3
    center_momentum: float = 0.9
    koleo_weight: float = 0.1
    freeze_last_layer_epochs: int = 1
    momentum_teacher: float = 0.99
    weight_decay: float = 0.04
    warmup_epochs: int = 1
    clip_grad: float = 3.0
    jitter: float = 0.4

    @classmethod
    def from_config(cls, pretrain: Mapping[str, Any]) -> DinoSettings:
        """Settings from config ``features.pretrain`` (its corpus and variant are the rules')."""
        return settings_from(cls, pretrain, where="features.pretrain", ignore=("corpus", "variant"))

    @classmethod
    def tiny(cls, **changes: Any) -> DinoSettings:
        """One epoch of a small head on small batches, for tests; `changes` override."""
        small = cls(
            epochs=1,
            batch_size=4,
            lr=1e-3,
            n_local_crops=2,
            out_dim=64,
            hidden_dim=32,
            bottleneck_dim=16,
        )
        return replace(small, **changes)


@dataclass(frozen=True)
class MaeSettings:
    """Masked-autoencoder pretraining (`mae.pretrain_mae`), from config ``features.mae``.

    epochs, batch_size, lr, weight_decay, warmup_epochs, seed: the run (AdamW, betas 0.9/0.95,
    cosine to 0 after the warm-up). `mask_ratio` of each frame's patches is hidden (MAE: 0.75).
    Decoder: `decoder_depth` blocks of width `decoder_dim` with `decoder_heads` heads.
    `norm_pix_loss`: targets normalised per patch (MAE's default).
    """

    epochs: int = 10
    batch_size: int = 64
    lr: float = 1.5e-3
    weight_decay: float = 0.05
    warmup_epochs: int = 1
    seed: int = 0
    mask_ratio: float = 0.75
    decoder_dim: int = 96
    decoder_depth: int = 1
    decoder_heads: int = 3
    norm_pix_loss: bool = True

    @classmethod
    def from_config(cls, mae: Mapping[str, Any]) -> MaeSettings:
        """Settings from config ``features.mae``."""
        return settings_from(cls, mae, where="features.mae")

    @classmethod
    def tiny(cls, **changes: Any) -> MaeSettings:
        """Two epochs of a narrow decoder on small batches, for tests; `changes` override."""
        return replace(cls(epochs=2, batch_size=8, decoder_dim=16, decoder_heads=2), **changes)


def backbones_pretrained(features: Mapping[str, Any]) -> bool:
    """Whether config ``features`` gives backbones that learned anything: DINO epochs above 0,
    or an official checkpoint for either modality (else they are the seeded random init)."""
    return int(features["pretrain"]["epochs"]) > 0 or any(
        features["backbones"][m].get("checkpoint") for m in ("vision", "tactile")
    )
