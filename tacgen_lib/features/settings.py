"""The features stage's settings: feature extraction (config ``features``), DINO and MAE
pretraining (``features.pretrain``, ``features.mae``) and the pretrained-vs-random check.

Every field that changes a pretrained backbone is a key of ``features.pretrain``, whose type,
default and bounds config/config.schema.yaml states (`io.schema.schema_fields`), so a run can be
reproduced from its config alone. ``corpus`` and ``variant`` (which frames the backbone learns
from) are read by the rules, not here. `DinoSettings.tiny()` is a
seconds-long run for tests.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from tacgen_lib.io.schema import SchemaSettings, schema_fields

__all__ = [
    "DinoSettings",
    "backbone_image_size",
    "FeatureSettings",
    "MaeSettings",
    "PretrainedVsRandomSettings",
    "SimclrSettings",
    "backbones_pretrained",
    "pretraining_corpora",
]


@dataclass(frozen=True)
@schema_fields(
    "features",
    skip=("backbones", "pretrain", "mae", "simclr", "pretrained_vs_random", "visibility"),
)
class FeatureSettings(SchemaSettings):
    """How a frozen backbone's features are extracted (config ``features``; `extract`).

    Frames are resized to `image_size` pixels and run through the backbone `batch_size` at a
    time; a frame's vector is its CLS token or the mean of its patch tokens (`pool`). The pixel
    features are the frame resized to `pixel_size` (H, W). `threads`: the torch threads of
    an extraction job (outputs are bit-identical at one count, not across counts).
    """

    @classmethod
    def for_backbone(cls, features: Mapping[str, Any], modality: str) -> FeatureSettings:
        """The settings of config ``features`` with the pool and the image size of the
        `modality` backbone (``features.backbones.<modality>.pool`` and ``.image_size`` where
        it names them, else features.pool and features.image_size)."""
        return cls.from_config(features).own(features["backbones"][modality])

    def own(self, backbone: Mapping[str, Any]) -> FeatureSettings:
        """These settings with the pool and image size a backbone declaration (`backbone`:
        features.backbones.<modality>, or a family's) names, where it names them."""
        out = replace(self, image_size=backbone_image_size(self.__dict__, backbone))
        return replace(out, pool=backbone["pool"]) if backbone.get("pool") else out


def backbone_image_size(features: Mapping[str, Any], backbone: Mapping[str, Any]) -> int:
    """The side in pixels a backbone declaration's frames are resized to (its own
    ``image_size``, else config ``features.image_size``; `FeatureSettings.own`): what its
    pretraining and its features read."""
    return int(backbone.get("image_size") or features["image_size"])


@dataclass(frozen=True)
@schema_fields("features.pretrain", skip=("corpus", "variant"))
class DinoSettings(SchemaSettings):
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
@schema_fields("features.mae")
class MaeSettings(SchemaSettings):
    """Masked-autoencoder pretraining (`mae.pretrain_mae`), from config ``features.mae``.

    epochs, batch_size, lr, weight_decay, warmup_epochs, seed: the run (AdamW, betas 0.9/0.95,
    cosine to 0 after the warm-up). `mask_ratio` of each frame's patches is hidden (MAE: 0.75).
    Decoder: `decoder_depth` blocks of width `decoder_dim` with `decoder_heads` heads.
    `norm_pix_loss`: targets normalised per patch (MAE's default).
    """

    @classmethod
    def tiny(cls, **changes: Any) -> MaeSettings:
        """Two epochs of a narrow decoder on small batches, for tests; `changes` override."""
        return replace(cls(epochs=2, batch_size=8, decoder_dim=16, decoder_heads=2), **changes)


@dataclass(frozen=True)
@schema_fields("features.simclr")
class SimclrSettings(SchemaSettings):
    """Contrastive pretraining of a ResNet (`simclr.pretrain_simclr`), from config
    ``features.simclr``: epochs, batch_size, lr, weight_decay, seed (the run); `tau` (the
    InfoNCE temperature), `crop_min` (the smallest crop's area fraction), `grey` (the
    probability of a greyscale view), `hidden_dim` and `proj_dim` (the projection)."""

    @classmethod
    def tiny(cls, **changes: Any) -> SimclrSettings:
        """One epoch of a narrow projection on small batches, for tests; `changes` override."""
        return replace(cls(epochs=1, batch_size=8, hidden_dim=16, proj_dim=8), **changes)


@dataclass(frozen=True)
@schema_fields("features.pretrained_vs_random")
class PretrainedVsRandomSettings(SchemaSettings):
    """The pretrained-vs-random check (config ``features.pretrained_vs_random``): a logistic
    probe of `targets` (modality -> manifest column) on `corpus`'s frames, from the pretrained
    and the random-init backbone, with `bootstrap` test resamples."""


def backbones_pretrained(features: Mapping[str, Any]) -> bool:
    """Whether config ``features`` gives backbones that learned anything: DINO epochs above 0,
    an official checkpoint, or an MAE or SimCLR objective for either modality (else they are
    the seeded random init)."""
    specs = [features["backbones"][m] for m in ("vision", "tactile")]
    return int(features["pretrain"]["epochs"]) > 0 or any(
        s.get("checkpoint") or s.get("objective") in ("mae", "simclr") for s in specs
    )


def pretraining_corpora(pretrain: Mapping[str, Any]) -> tuple[str, ...]:
    """The corpora whose train frames pretraining reads (config ``features.pretrain.corpus``:
    one name or a list), in the config's order."""
    corpus = pretrain["corpus"]
    return (corpus,) if isinstance(corpus, str) else tuple(corpus)
