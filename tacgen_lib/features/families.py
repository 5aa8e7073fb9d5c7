"""Backbone families: which frozen encoders the comparison of families runs, read from config
``backbones`` (plain Python, no torch: the Snakefile reads it at parse time).

A family names one backbone per modality (`features.backbones`' shape: an `arch`, an optional
official `checkpoint`, and how it is made without one, `objective`: "dino", "mae", "simclr" or "random"). The paper
checks that the V+T direction holds for several encoder families (DINOv2, CLIP + MAE, Sparsh);
here the families are the DINOv2-architecture ViT, a torchvision-shaped ResNet and an MAE-
pretrained ViT. A family whose two backbones are the main DAG's (`features.backbones`, the same
arch, checkpoint and objective) is the *main* family: its probes read the main feature edges,
so nothing is computed twice.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from tacgen_lib.features.archs import arch_family
from tacgen_lib.features.settings import MaeSettings
from tacgen_lib.io.config import ConfigError, settings_from
from tacgen_lib.io.schema import SchemaSettings, not_config, schema_fields

__all__ = [
    "BackboneSpec",
    "FamilySettings",
    "MODALITIES",
    "OFFICIAL_CHECKPOINTS",
    "check_backbone",
    "check_checkpoint_file",
]

MODALITIES = ("vision", "tactile")


@dataclass(frozen=True)
@schema_fields("features.backbones.vision")
class BackboneSpec(SchemaSettings):
    """One modality's backbone: arch, official checkpoint (or None), pretraining objective.

    Every backbone declaration (features.backbones.vision and .tactile, a family's under
    backbones.families) is one schema ($defs/backbone); the fields name the keys of the
    vision one.
    """

    @classmethod
    def from_config(
        cls, spec: Mapping[str, Any], where: str = "features.backbones.vision"
    ) -> BackboneSpec:
        """The backbone a declaration `spec` (at config key `where`) gives; an empty
        checkpoint is none."""
        out = settings_from(cls, spec, where=where)
        return replace(out, checkpoint=out.checkpoint or None)

    @property
    def network(self) -> str:
        """ "vit" or "resnet" (archs.arch_family)."""
        return arch_family(self.arch)

    def pretrains(self, dino_epochs: int) -> bool:
        """Whether making it trains on frames (not a checkpoint, not the random init: an
        objective other than random, and DINO only at `dino_epochs` above 0)."""
        if self.checkpoint or self.objective == "random":
            return False
        return self.objective != "dino" or dino_epochs > 0

    def label(self, dino_epochs: int) -> str:
        """What the report says of it: arch, then how it was made (a DINO objective at 0
        epochs of features.pretrain is the random init)."""
        if self.checkpoint:
            return f"{self.arch} (checkpoint)"
        if not self.pretrains(dino_epochs):
            return f"{self.arch} (random init)"
        return f"{self.arch} ({self.objective.upper()})"


def check_backbone(
    spec: BackboneSpec,
    *,
    where: str,
    dino_epochs: int,
    mae_epochs: int,
    features_pool: str,
) -> None:
    """Refuse a backbone the workflow cannot make or read. Objectives: "dino" (a ViT; DINO with
    features.pretrain, whose 0 epochs mean the seeded random init), "mae" (a ViT; features.mae,
    at least 1 epoch), "simclr" (a ResNet; features.simclr), "random" (any arch: the seeded
    random init). A ResNet is pretrained in the workflow by SimCLR only, a ViT by DINO or MAE.
    Its pool (`spec.pool`, else `features_pool`, config features.pool) "stages" needs a
    ResNet."""
    if (spec.pool or features_pool) == "stages" and spec.network != "resnet":
        key = "pool" if spec.pool else "features.pool"
        raise ConfigError(
            f"config {where}: {key} stages reads a ResNet's stage statistics; the ViT "
            f"{spec.arch} takes pool cls or mean_patch (say {where}.pool: null, or cls, where "
            "a ViT replaces the default's ResNet vision side)"
        )
    if spec.checkpoint:
        return
    if spec.network == "resnet" and spec.objective not in ("random", "simclr"):
        raise ConfigError(
            f"config {where}: a ResNet ({spec.arch}) has no in-workflow {spec.objective} "
            "pretraining here; give it a torchvision checkpoint, objective: simclr "
            "(features.simclr) or objective: random (its seeded random init)"
        )
    if spec.network == "vit" and spec.objective == "simclr":
        raise ConfigError(
            f"config {where}: objective simclr pretrains a ResNet (resnet_tiny, resnet18), "
            f"not the ViT {spec.arch}; a ViT takes dino or mae"
        )
    if spec.objective == "mae" and mae_epochs < 1:
        raise ConfigError(f"config {where}: objective mae needs features.mae.epochs >= 1")


#: The official checkpoints the workflow loads, by file name: where each is published (the
#: file is downloaded once into `models/`; nothing is fetched during a run).
OFFICIAL_CHECKPOINTS = {
    "dinov2_vits14_pretrain.pth": "https://dl.fbaipublicfiles.com/dinov2/dinov2_vits14/"
    "dinov2_vits14_pretrain.pth (DINOv2 ViT-S/14, github.com/facebookresearch/dinov2, "
    "README 'Pretrained models')",
    "dinov2_vitb14_pretrain.pth": "https://dl.fbaipublicfiles.com/dinov2/dinov2_vitb14/"
    "dinov2_vitb14_pretrain.pth (DINOv2 ViT-B/14, github.com/facebookresearch/dinov2, "
    "README 'Pretrained models')",
    "mae_pretrain_vit_base.pth": "https://dl.fbaipublicfiles.com/mae/pretrain/"
    "mae_pretrain_vit_base.pth (MAE ViT-B/16 encoder, github.com/facebookresearch/mae, "
    "PRETRAIN.md / README 'pre-trained checkpoints')",
    "resnet18-f37072fd.pth": "https://download.pytorch.org/models/resnet18-f37072fd.pth "
    "(torchvision ResNet18_Weights.IMAGENET1K_V1)",
}


def check_checkpoint_file(
    spec: BackboneSpec, *, where: str, root: str | os.PathLike[str] = "."
) -> None:
    """Refuse, before any job runs, a backbone whose `checkpoint` names no file: the error
    names the config key, the file expected (relative paths against `root`, the workflow's
    working directory), where the official weights of that name are published, and the key
    that pretrains in the workflow instead. A backbone without a checkpoint passes."""
    if not spec.checkpoint:
        return
    path = Path(spec.checkpoint)
    full = path if path.is_absolute() else Path(root) / path
    if full.is_file():
        return
    published = OFFICIAL_CHECKPOINTS.get(path.name)
    where_from = (
        f"the official weights of that name are published at {published}"
        if published
        else f"no official release is named {path.name!r} (known: {sorted(OFFICIAL_CHECKPOINTS)})"
    )
    raise ConfigError(
        f"config {where}.checkpoint: {spec.checkpoint} not found (expected the file "
        f"{path.name} at {full}); {where_from}: download it there, or set {where}.checkpoint: "
        "null to make this backbone in the workflow instead (features.pretrain / features.mae; "
        "`make estimate` prices it)"
    )


@dataclass(frozen=True)
@schema_fields("backbones", skip=("families",))
class FamilySettings(SchemaSettings):
    """Config ``backbones``: the families compared (`run`, in order), their specs, the probe
    families (config ``probes.families`` names) each is judged on and the probe protocols
    (raw linear and the 2-layer MLP); keys, defaults and bounds are the schema's."""

    #: family -> modality -> its backbone, each declaration read (and held to the schema's
    #: $defs/backbone) by `BackboneSpec`
    families: Mapping[str, Mapping[str, BackboneSpec]] = not_config(default_factory=dict)

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> FamilySettings:
        """The families of the whole config's ``backbones`` (the probe families it names are
        checked against ``probes.families``)."""
        cfg = dict(config["backbones"])
        families = {
            name: {
                m: BackboneSpec.from_config(spec[m], f"backbones.families.{name}.{m}")
                for m in MODALITIES
            }
            for name, spec in cfg.pop("families").items()
        }
        settings = settings_from(cls, cfg, where="backbones", families=families)
        unknown = [f for f in settings.run if f not in families]
        if unknown:
            raise ConfigError(
                f"config backbones.run: unknown family {unknown[0]!r} (backbones.families: "
                f"{sorted(families)})"
            )
        known = config["probes"]["families"]
        missing = [p for p in settings.probes if p not in known]
        if missing:
            raise ConfigError(
                f"config backbones.probes: {missing[0]!r} is not a probe family "
                f"(probes.families: {sorted(known)})"
            )
        flat = [p for p in settings.probes if known[p].get("vision") == "pixel"]
        if flat:
            raise ConfigError(
                f"config backbones.probes: {flat[0]!r} compares pixel V; a backbone family is "
                "judged on families whose V is the backbone's (vision: vit)"
            )
        feats = config["features"]
        for name in settings.run:
            for m in MODALITIES:
                check_backbone(
                    families[name][m],
                    where=f"backbones.families.{name}.{m}",
                    dino_epochs=int(feats["pretrain"]["epochs"]),
                    mae_epochs=MaeSettings.from_config(feats["mae"]).epochs,
                    features_pool=feats["pool"],
                )
        return settings

    def is_main(self, family: str, features: Mapping[str, Any]) -> bool:
        """Whether `family`'s two backbones are the main DAG's (`features.backbones`)."""
        return all(
            self.families[family][m] == BackboneSpec.from_config(features["backbones"][m])
            for m in MODALITIES
        )

    def own(self, features: Mapping[str, Any]) -> list[str]:
        """The families run that are not the main one: they get their own backbones and
        feature edges."""
        return [f for f in self.run if not self.is_main(f, features)]
