"""The convolutional backbone family: a ResNet with torchvision's parameter names.

A compact re-implementation of torchvision's `ResNet` with `BasicBlock`s (torchvision cannot be
imported beside this project's CPU torch build), whose state-dict names are torchvision's, so an
official `resnet18-f37072fd.pth` loads without renaming:

    conv1.weight, bn1.{weight,bias,running_mean,running_var,num_batches_tracked}
    layer{1..4}.{i}.conv1 / bn1 / conv2 / bn2 / downsample.0 (1x1 conv) / downsample.1 (BN)
    fc.{weight,bias}            (the ImageNet classifier: accepted in a checkpoint, not kept)

Names and the initialisation (Kaiming-normal fan-out convolutions, BN weight 1 and bias 0) were
checked against torchvision/models/resnet.py; the code is our own. The frozen feature of a frame
is the global average of the last stage (torchvision's `avgpool` + `flatten`): `forward_features`
returns it under the ViT's dict keys (`x_norm_clstoken`, and the last stage's spatial cells as
`x_norm_patchtokens`), so `extract.extract_features` pools a ResNet as it pools a ViT. Its
"stages" pool reads `stage_statistics` instead: the first three stages' std over space and
the last stage's mean.
"""

from __future__ import annotations

import re
from pathlib import Path

import torch
from torch import Tensor, nn

from tacgen_lib.features.archs import RESNET_ARCHS, ResNetConfig
from tacgen_lib.features.vit_checkpoint import state_dict_mismatch

__all__ = [
    "BasicBlock",
    "ResNet",
    "build_resnet",
    "load_resnet_checkpoint",
    "random_resnet",
    "resnet_from_state_dict",
]


class BasicBlock(nn.Module):
    """Two 3x3 convolutions with BN and a residual (torchvision's BasicBlock, expansion 1)."""

    def __init__(self, inplanes: int, planes: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(inplanes, planes, 3, stride=stride, padding=1, bias=False)
        self.bn1 = nn.BatchNorm2d(planes)
        self.conv2 = nn.Conv2d(planes, planes, 3, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(planes)
        self.relu = nn.ReLU(inplace=True)
        self.downsample: nn.Module | None = None
        if stride != 1 or inplanes != planes:
            self.downsample = nn.Sequential(
                nn.Conv2d(inplanes, planes, 1, stride=stride, bias=False), nn.BatchNorm2d(planes)
            )

    def forward(self, x: Tensor) -> Tensor:
        identity = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        return self.relu(self.bn2(self.conv2(out)) + identity)


class ResNet(nn.Module):
    """Stem (7x7/2 conv, BN, ReLU, 3x3/2 max-pool), four stages of BasicBlocks, global pool.

    `num_features` is the last stage's width. No classifier: the frozen features are the pooled
    last stage (a checkpoint's `fc.*` is dropped on load).
    """

    def __init__(self, config: ResNetConfig) -> None:
        super().__init__()
        if len(config.blocks) != 4 or len(config.widths) != 4:
            raise ValueError(f"a ResNet has four stages, got {config}")
        self.config = config
        self.embed_dim = self.num_features = config.widths[-1]
        # any input side works (strides are padded): no patch grid constrains the image size
        self.patch_size = 1
        stem = config.widths[0]
        self.conv1 = nn.Conv2d(3, stem, 7, stride=2, padding=3, bias=False)
        self.bn1 = nn.BatchNorm2d(stem)
        self.relu = nn.ReLU(inplace=True)
        self.maxpool = nn.MaxPool2d(3, stride=2, padding=1)
        inplanes = stem
        for i, (n, width) in enumerate(zip(config.blocks, config.widths, strict=True)):
            stride = 1 if i == 0 else 2
            layer = []
            for j in range(n):
                layer.append(BasicBlock(inplanes, width, stride if j == 0 else 1))
                inplanes = width
            setattr(self, f"layer{i + 1}", nn.Sequential(*layer))
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
            elif isinstance(m, nn.BatchNorm2d):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)

    def forward_features(self, x: Tensor) -> dict[str, Tensor]:
        """The pooled last stage as `x_norm_clstoken` (B, C); its H*W cells as
        `x_norm_patchtokens` (B, H*W, C). Their mean is the pooled feature, so both of
        `extract_features`' pools give torchvision's avgpool output."""
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"expected images (B, 3, H, W), got shape {tuple(x.shape)}")
        x = self.maxpool(self.relu(self.bn1(self.conv1(x))))
        for i in range(1, 5):
            x = getattr(self, f"layer{i}")(x)
        cells = x.flatten(2).transpose(1, 2)
        return {"x_norm_clstoken": cells.mean(dim=1), "x_norm_patchtokens": cells}

    def forward(self, x: Tensor) -> Tensor:
        """The pooled feature (B, C)."""
        return self.forward_features(x)["x_norm_clstoken"]

    def stage_statistics(self, x: Tensor) -> Tensor:
        """The standard deviation over space of the first three stages' maps, then the last
        stage's mean ([std_1, std_2, std_3, mean_4]; (B, sum(widths))). The mean is the usual
        pooled feature; each std is a stage's texture energy, the first-order form of the
        texture statistics of Gatys et al. (2015). The early stages see neighbourhoods of a
        few pixels, so they keep the fine texture that the last stage's global average blurs
        away (pool "stages" of `extract.extract_features`). The std is the population one
        (divided by H*W)."""
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"expected images (B, 3, H, W), got shape {tuple(x.shape)}")
        x = self.maxpool(self.relu(self.bn1(self.conv1(x))))
        parts = []
        for i in range(1, 5):
            x = getattr(self, f"layer{i}")(x)
            var, mean = torch.var_mean(x.flatten(2), dim=2, correction=0)
            parts.append(mean if i == 4 else var.sqrt())
        return torch.cat(parts, dim=1)

    @property
    def stage_statistics_dim(self) -> int:
        """Width of `stage_statistics`: the sum of the stage widths."""
        return sum(self.config.widths)


def build_resnet(arch: str) -> ResNet:
    """A freshly initialised ResNet of a named architecture (see archs.RESNET_ARCHS)."""
    if arch not in RESNET_ARCHS:
        raise ValueError(f"unknown ResNet arch {arch!r}; valid: {sorted(RESNET_ARCHS)}")
    return ResNet(RESNET_ARCHS[arch])


def random_resnet(arch: str, seed: int) -> ResNet:
    """The seeded random-init ResNet of `arch` in eval mode (BN uses its running statistics,
    mean 0 and variance 1 at init). Drawn under a forked RNG: the caller's torch RNG is
    untouched."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return build_resnet(arch).eval()


_CLASSIFIER = re.compile(r"^fc\.")


def load_resnet_checkpoint(model: ResNet, sd: dict[str, Tensor], *, where: str) -> ResNet:
    """Load a torchvision-format state dict into `model` (in place; also returned).

    The classifier (`fc.*`) is dropped. Any other missing, unexpected or shape-mismatched key is
    refused with a ValueError naming `where` and every such key.
    """
    sd = {k: v for k, v in sd.items() if not _CLASSIFIER.match(k)}
    own = model.state_dict()
    problems = state_dict_mismatch(own, sd)
    if problems:
        raise ValueError(
            f"{where}: checkpoint does not fit the ResNet {model.config}; {problems}. "
            "Name the matching arch (tacgen_lib.features.archs.RESNET_ARCHS)."
        )
    model.load_state_dict({k: v.to(own[k].dtype) for k, v in sd.items()}, strict=True)
    return model.eval()


def resnet_from_state_dict(sd: dict[str, Tensor], *, where: str | Path) -> ResNet:
    """Build the ResNet a state dict describes (blocks per stage from the `layer{i}.{j}` keys,
    widths from each stage's first conv) and load it. A shape no named arch has is refused."""
    blocks, widths = [], []
    for i in range(1, 5):
        idx = {int(k.split(".")[1]) for k in sd if k.startswith(f"layer{i}.")}
        if not idx:
            raise ValueError(f"{where}: no layer{i}.* keys; not a torchvision-format ResNet")
        blocks.append(max(idx) + 1)
        widths.append(int(sd[f"layer{i}.0.conv1.weight"].shape[0]))
    shape = ResNetConfig(blocks=tuple(blocks), widths=tuple(widths))
    matches = [a for a, c in RESNET_ARCHS.items() if c == shape]
    if not matches:
        raise ValueError(f"{where}: no known ResNet arch has {shape}; known: {RESNET_ARCHS}")
    return load_resnet_checkpoint(build_resnet(matches[0]), sd, where=str(where))
