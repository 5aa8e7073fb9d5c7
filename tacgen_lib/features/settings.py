"""The features stage's settings: DINO pretraining from config ``features.pretrain``.

Every field that changes a pretrained backbone is a key of ``features.pretrain``, whose default
and bounds config/config.schema.yaml states (`io.schema.setting`), so a run can be reproduced
from its config alone. ``corpus`` and ``variant`` (which
frames the backbone learns from) are read by the rules, not here. `DinoSettings.tiny()` is a
seconds-long run for tests.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

from tacgen_lib.io.config import settings_from
from tacgen_lib.io.schema import check_settings, setting

__all__ = [
    "DinoSettings",
    "FeatureSettings",
    "MaeSettings",
    "PretrainedVsRandomSettings",
    "backbones_pretrained",
]


@dataclass(frozen=True)
class FeatureSettings:
    """How a frozen backbone's features are extracted (config ``features``; `extract`).

    Frames are resized to `image_size` pixels and run through the backbone `batch_size` at a
    time; a frame's vector is its CLS token or the mean of its patch tokens (`pool`). The pixel
    features are the frame resized to `pixel_size` (H, W). `threads`: the torch threads of
    an extraction job (outputs are bit-identical at one count, not across counts).
    """

    image_size: int = setting("features.image_size")
    pool: Literal["cls", "mean_patch"] = setting("features.pool")
    batch_size: int = setting("features.batch_size")
    pixel_size: tuple[int, int] = setting("features.pixel_size")
    threads: int = setting("features.threads")

    def __post_init__(self) -> None:
        check_settings(self)

    @classmethod
    def from_config(cls, features: Mapping[str, Any]) -> FeatureSettings:
        """Settings from config ``features`` (its subsections have their own objects)."""
        subsections = ("backbones", "pretrain", "mae", "pretrained_vs_random", "visibility")
        return settings_from(cls, features, where="features", ignore=subsections)


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

    epochs: int = setting("features.pretrain.epochs")
    batch_size: int = setting("features.pretrain.batch_size")
    lr: float = setting("features.pretrain.lr")
    seed: int = setting("features.pretrain.seed")
    n_local_crops: int = setting("features.pretrain.n_local_crops")
    local_size: int | None = setting("features.pretrain.local_size")
    out_dim: int = setting("features.pretrain.out_dim")
    hidden_dim: int = setting("features.pretrain.hidden_dim")
    bottleneck_dim: int = setting("features.pretrain.bottleneck_dim")
    student_temp: float = setting("features.pretrain.student_temp")
    teacher_temp: float = setting("features.pretrain.teacher_temp")
    warmup_teacher_temp: float | None = setting("features.pretrain.warmup_teacher_temp")
    warmup_teacher_temp_epochs: int = setting("features.pretrain.warmup_teacher_temp_epochs")
    centering: Literal["sinkhorn_knopp", "centre"] = setting("features.pretrain.centering")
    sinkhorn_iterations: int = setting("features.pretrain.sinkhorn_iterations")
    center_momentum: float = setting("features.pretrain.center_momentum")
    koleo_weight: float = setting("features.pretrain.koleo_weight")
    freeze_last_layer_epochs: int = setting("features.pretrain.freeze_last_layer_epochs")
    momentum_teacher: float = setting("features.pretrain.momentum_teacher")
    weight_decay: float = setting("features.pretrain.weight_decay")
    warmup_epochs: int = setting("features.pretrain.warmup_epochs")
    clip_grad: float = setting("features.pretrain.clip_grad")
    jitter: float = setting("features.pretrain.jitter")

    def __post_init__(self) -> None:
        check_settings(self)

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

    epochs: int = setting("features.mae.epochs")
    batch_size: int = setting("features.mae.batch_size")
    lr: float = setting("features.mae.lr")
    weight_decay: float = setting("features.mae.weight_decay")
    warmup_epochs: int = setting("features.mae.warmup_epochs")
    seed: int = setting("features.mae.seed")
    mask_ratio: float = setting("features.mae.mask_ratio")
    decoder_dim: int = setting("features.mae.decoder_dim")
    decoder_depth: int = setting("features.mae.decoder_depth")
    decoder_heads: int = setting("features.mae.decoder_heads")
    norm_pix_loss: bool = setting("features.mae.norm_pix_loss")

    def __post_init__(self) -> None:
        check_settings(self)

    @classmethod
    def from_config(cls, mae: Mapping[str, Any]) -> MaeSettings:
        """Settings from config ``features.mae``."""
        return settings_from(cls, mae, where="features.mae")

    @classmethod
    def tiny(cls, **changes: Any) -> MaeSettings:
        """Two epochs of a narrow decoder on small batches, for tests; `changes` override."""
        return replace(cls(epochs=2, batch_size=8, decoder_dim=16, decoder_heads=2), **changes)


@dataclass(frozen=True)
class PretrainedVsRandomSettings:
    """The pretrained-vs-random check (config ``features.pretrained_vs_random``): a logistic
    probe of `targets` (modality -> manifest column) on `corpus`'s frames, from the pretrained
    and the random-init backbone, with `bootstrap` test resamples."""

    corpus: str = setting("features.pretrained_vs_random.corpus")
    targets: Mapping[str, str] = setting("features.pretrained_vs_random.targets")
    bootstrap: int = setting("features.pretrained_vs_random.bootstrap")

    def __post_init__(self) -> None:
        check_settings(self)

    @classmethod
    def from_config(cls, check: Mapping[str, Any]) -> PretrainedVsRandomSettings:
        """Settings from config ``features.pretrained_vs_random``."""
        return settings_from(cls, check, where="features.pretrained_vs_random")


def backbones_pretrained(features: Mapping[str, Any]) -> bool:
    """Whether config ``features`` gives backbones that learned anything: DINO epochs above 0,
    or an official checkpoint for either modality (else they are the seeded random init)."""
    return int(features["pretrain"]["epochs"]) > 0 or any(
        features["backbones"][m].get("checkpoint") for m in ("vision", "tactile")
    )
