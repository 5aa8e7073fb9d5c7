"""pix2pix (Isola et al. 2017), scaled down: RGB frame -> tactile frame by a conditional GAN.

This module owns the translator G (`UNetTranslator`), the conditional PatchGAN D
(`PatchDiscriminator`, its `receptive_field`), their training (`fit_pix2pix`: the objective of
paper eq. 4, GAN loss + lambda L1, early-stopped on the val split's L1) and `translate`.

Two departures from the paper, both deliberate:

- the translator's output is linear, not tanh: the tactile target lies in [-1, 127/128] with
  the background exactly 0, and a tanh would squash the contact peaks towards the bounds and
  hide an overshoot; outputs are never clipped, so a bad model shows;
- `translate` runs G in eval mode (dropout off, BatchNorm on its running statistics): the
  paper kept dropout at test time as G's only noise; here one RGB frame gives one tactile
  frame, deterministically.

Bit-reproducible on one machine: `fit_pix2pix` runs inside ``torch.random.fork_rng`` seeded
with `seed` (the initial weights and the dropout masks), minibatches come from a
``torch.Generator`` seeded with `seed`; the caller's global RNG is left as it was.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from tacgen_lib.generate.pixel.pixel_fit import PixelFit
from tacgen_lib.generate.pixel.settings import Pix2PixSettings, frames_tensor
from tacgen_lib.generate.stopping import EarlyStopping
from tacgen_lib.optim import AdamW

__all__ = [
    "CURVE_COLUMNS",
    "PatchDiscriminator",
    "Pix2PixFit",
    "UNetTranslator",
    "fit_pix2pix",
    "gan_init",
    "make_pix2pix_optimisers",
    "pix2pix_step",
    "receptive_field",
    "translate",
]

#: Columns of `Pix2PixFit.curve`; row step 0 is the untrained G (training columns NaN).
CURVE_COLUMNS = ("step", "g_loss", "d_loss", "l1_train", "val_l1")
#: Decoder layers with dropout, innermost first (the paper's first three).
_DROPOUT_LAYERS = 3
#: Frames per batch of the val L1's translations while G trains (`fit_pix2pix`); the sampling
#: job's batch is config ``pixel.batch``.
_VAL_BATCH = 256


def gan_init(module: nn.Module) -> None:
    """Isola et al.'s initialisation (after DCGAN): conv weights ~ N(0, 0.02), BatchNorm
    scales ~ N(1, 0.02), biases 0. Draws from torch's global RNG (seed it around the call)."""
    if isinstance(module, nn.Conv2d | nn.ConvTranspose2d):
        nn.init.normal_(module.weight, 0.0, 0.02)
        if module.bias is not None:
            nn.init.zeros_(module.bias)
    elif isinstance(module, nn.BatchNorm2d):
        nn.init.normal_(module.weight, 1.0, 0.02)
        nn.init.zeros_(module.bias)


class UNetTranslator(nn.Module):
    """G: U-Net from a (B, 3, H, W) RGB frame to a (B, 3, H, W) tactile frame.

    Encoder: per width c in `channels`, Conv 4x4 stride 2 + BatchNorm (not on the first) +
    LeakyReLU(0.2). Decoder, mirrored: ConvTranspose 4x4 stride 2 + BatchNorm + ReLU, then
    concatenation with the encoder output of the same size (skip); dropout `dropout` on the
    innermost decoder layers (up to three, as the paper's). A last ConvTranspose to 3
    channels, with no activation: linear output, because the target range is
    [-1, 127/128] with the background at 0 and must not be squashed by a tanh.
    H and W must be multiples of 2 ** len(channels).
    """

    def __init__(self, channels: Sequence[int], dropout: float) -> None:
        super().__init__()
        widths = [int(c) for c in channels]
        self.channels = tuple(widths)
        self.encoder = nn.ModuleList()
        c_in = 3
        for i, c in enumerate(widths):
            layers: list[nn.Module] = [nn.Conv2d(c_in, c, 4, 2, 1, bias=i == 0)]
            if i > 0:
                layers.append(nn.BatchNorm2d(c))
            layers.append(nn.LeakyReLU(0.2))
            self.encoder.append(nn.Sequential(*layers))
            c_in = c
        self.decoder = nn.ModuleList()
        for j, i in enumerate(range(len(widths) - 1, 0, -1)):  # j = 0 is the innermost layer
            layers = [nn.ConvTranspose2d(c_in, widths[i - 1], 4, 2, 1, bias=False)]
            layers.append(nn.BatchNorm2d(widths[i - 1]))
            if dropout > 0 and j < _DROPOUT_LAYERS:
                layers.append(nn.Dropout(dropout))
            layers.append(nn.ReLU())
            self.decoder.append(nn.Sequential(*layers))
            c_in = 2 * widths[i - 1]  # after the skip concatenation
        self.out = nn.ConvTranspose2d(c_in, 3, 4, 2, 1)
        self.apply(gan_init)

    def forward(self, rgb: Tensor) -> Tensor:
        skips = []
        h = rgb
        for layer in self.encoder:
            h = layer(h)
            skips.append(h)
        h = skips.pop()  # the bottleneck
        for layer in self.decoder:
            h = torch.cat([layer(h), skips.pop()], dim=1)
        return self.out(h)


class PatchDiscriminator(nn.Module):
    """D: conditional PatchGAN, (RGB, tactile) -> a map of real/fake logits, one per patch.

    Input concat(RGB, tactile) = 6 channels; per width in `disc_channels` a Conv 4x4 stride 2
    + BatchNorm (not on the first) + LeakyReLU(0.2); then a stride-1 4x4 conv to 1 channel.
    Each logit sees a `receptive_field(disc_channels)`-pixel square of the input.
    """

    def __init__(self, disc_channels: Sequence[int]) -> None:
        super().__init__()
        widths = [int(c) for c in disc_channels]
        self.disc_channels = tuple(widths)
        layers: list[nn.Module] = []
        c_in = 6
        for i, c in enumerate(widths):
            layers.append(nn.Conv2d(c_in, c, 4, 2, 1, bias=i == 0))
            if i > 0:
                layers.append(nn.BatchNorm2d(c))
            layers.append(nn.LeakyReLU(0.2))
            c_in = c
        layers.append(nn.Conv2d(c_in, 1, 4, 1, 1))
        self.net = nn.Sequential(*layers)
        self.apply(gan_init)

    def forward(self, rgb: Tensor, tactile: Tensor) -> Tensor:
        return self.net(torch.cat([rgb, tactile], dim=1))


def receptive_field(disc_channels: Sequence[int]) -> int:
    """Side in pixels of the input square one logit of `PatchDiscriminator` sees.

    Back from one output pixel through the 4x4 convolutions (stride 2 per width, then the
    stride-1 output conv): r <- (r - 1) stride + kernel, from r = 1. The paper's 70x70 PatchGAN
    is this recursion with widths (64, 128, 256) and one more stride-1 layer.
    """
    r = 1
    for kernel, stride in reversed([(4, 2)] * len(disc_channels) + [(4, 1)]):
        r = (r - 1) * stride + kernel
    return r


@dataclass(frozen=True, eq=False)
class Pix2PixFit(PixelFit):
    """A trained translator G (eval mode) and how it was trained (`PixelFit`; curve columns
    `CURVE_COLUMNS`, the training columns means over the steps since the previous row;
    best_val a val L1).
    """


def translate(model: UNetTranslator, rgb: np.ndarray, batch: int) -> np.ndarray:
    """Tactile frames (N, 3, H, W) float32 for RGB frames (N, 3, H, W), never clipped.

    G runs in eval mode (dropout off, BatchNorm on running statistics), so the result is
    deterministic: one tactile frame per RGB frame (the paper kept dropout on as noise). The
    model's train/eval mode is restored afterwards. It runs on the model's device (the frames
    move there in batches; on the CPU no move).
    """
    x = frames_tensor(rgb, "rgb", divisor=2 ** len(model.channels))
    dev = next(model.parameters()).device
    was_training = model.training
    model.eval()
    try:
        with torch.inference_mode():
            out = [
                model(x[s : s + batch].to(dev)).cpu().numpy() for s in range(0, x.shape[0], batch)
            ]
    finally:
        model.train(was_training)
    if not out:
        return np.zeros(x.shape, dtype=np.float32)
    return np.concatenate(out)


def _pairs(
    rgb: np.ndarray, tac: np.ndarray, split: str, divisor: int, size: tuple[int, int] | None
) -> tuple[Tensor, Tensor]:
    x = frames_tensor(rgb, f"rgb_{split}", divisor=divisor)
    y = frames_tensor(tac, f"tac_{split}", divisor=divisor)
    if x.shape != y.shape:
        raise ValueError(
            f"{split}: RGB frames {tuple(x.shape)} and tactile frames {tuple(y.shape)} differ; "
            "row i of each must be one pair at one size"
        )
    if size is not None and x.shape[0] and tuple(x.shape[2:]) != size:
        raise ValueError(f"{split}: frame size {tuple(x.shape[2:])} differs from train's {size}")
    return x, y


def pix2pix_step(
    g: UNetTranslator,
    d: PatchDiscriminator,
    opt_g: AdamW,
    opt_d: AdamW,
    x: Tensor,
    y: Tensor,
    lambda_l1: float,
) -> tuple[Tensor, Tensor, Tensor]:
    """One step of both nets on RGB x and tactile y (paper eq. 4); returns (G loss, D loss, L1).

    1. D: 0.5 (BCE(D(x, y), 1) + BCE(D(x, G(x)), 0)), optimiser step (G(x) detached)
    2. G: BCE(D(x, G(x)), 1) + lambda_l1 mean |G(x) - y|, optimiser step (D frozen; D stays
       in train mode, so its BatchNorm sees this batch, as in the paper's code)
    """
    fake = g(x)
    d.requires_grad_(True)
    real_logits, fake_logits = d(x, y), d(x, fake.detach())
    loss_d = 0.5 * (
        F.binary_cross_entropy_with_logits(real_logits, torch.ones_like(real_logits))
        + F.binary_cross_entropy_with_logits(fake_logits, torch.zeros_like(fake_logits))
    )
    opt_d.zero_grad(set_to_none=True)
    loss_d.backward()
    opt_d.step()
    d.requires_grad_(False)
    fake_logits = d(x, fake)
    l1 = torch.mean(torch.abs(fake - y))
    loss_g = (
        F.binary_cross_entropy_with_logits(fake_logits, torch.ones_like(fake_logits))
        + lambda_l1 * l1
    )
    opt_g.zero_grad(set_to_none=True)
    loss_g.backward()
    opt_g.step()
    return loss_g, loss_d, l1


def make_pix2pix_optimisers(
    g: UNetTranslator, d: PatchDiscriminator, settings: Pix2PixSettings
) -> tuple[AdamW, AdamW]:
    """Adam for G and for D: `tacgen_lib.optim.AdamW` with weight decay 0 (the same update as
    Adam), lr ``settings.lr``, betas (``beta1``, 0.999), torch's fused kernel."""
    betas = (settings.beta1, 0.999)

    def adam(m: nn.Module) -> AdamW:
        return AdamW(
            list(m.parameters()), lr=settings.lr, betas=betas, weight_decay=0.0, fused=True
        )

    return adam(g), adam(d)


def fit_pix2pix(
    rgb_train: np.ndarray,
    tac_train: np.ndarray,
    rgb_val: np.ndarray,
    tac_val: np.ndarray,
    settings: Pix2PixSettings,
    seed: int,
    progress: Callable[[str], Any] | None = None,
    *,
    device: torch.device | str,
) -> Pix2PixFit:
    """Train G and D on train pairs (paper eq. 4), keep the G with the lowest val L1.

    Per step, `pix2pix_step` on a minibatch (x, y) of ``batch_size`` pairs drawn with
    replacement (D, then G; Adam from `make_pix2pix_optimisers`). Every ``eval_every`` steps
    (and at the last) the mean absolute error of `translate` on the val pairs; the best G is
    kept (a deep copy of its state), and training stops after ``patience`` evaluations
    without improvement (0: never).

    device: where G and D train (`tacgen_lib.runtime.device`): initialised and the batches
    drawn on the CPU, then moved (on the CPU no move); G comes back on the CPU. On a GPU the
    dropout masks come from the GPU's generator (seeded with `seed` too).
    """
    say = progress or (lambda _m: None)
    levels = len(settings.channels)
    x_tr, y_tr = _pairs(rgb_train, tac_train, "train", 2**levels, None)
    if x_tr.shape[0] < 1:
        raise ValueError("fit_pix2pix: no train pairs")
    size = (int(x_tr.shape[2]), int(x_tr.shape[3]))
    x_va, y_va = _pairs(rgb_val, tac_val, "val", 2**levels, size)
    n_disc = len(settings.disc_channels)
    if min(size) // 2**n_disc < 2:
        raise ValueError(
            f"fit_pix2pix: frames {size[0]}x{size[1]} leave no PatchGAN output after "
            f"{n_disc} stride-2 layers (need H, W >= {2 ** (n_disc + 1)}); use fewer disc_channels"
        )
    y_va_np = y_va.numpy()

    def val_l1(g: UNetTranslator) -> float:
        if x_va.shape[0] == 0:
            return float("nan")
        pred = translate(g, x_va.numpy(), _VAL_BATCH)
        return float(np.mean(np.abs(pred - y_va_np), dtype=np.float64))

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))  # initial weights and dropout masks
        g, d = (
            UNetTranslator(settings.channels, settings.dropout),
            PatchDiscriminator(settings.disc_channels),
        )
        dev = torch.device(device)
        g.to(dev)
        d.to(dev)
        x_tr, y_tr = x_tr.to(dev), y_tr.to(dev)
        opt_g, opt_d = make_pix2pix_optimisers(g, d, settings)
        gen = torch.Generator().manual_seed(int(seed))
        n, bs = x_tr.shape[0], min(settings.batch_size, x_tr.shape[0])

        vl0 = val_l1(g)
        curve: list[dict] = [
            {"step": 0, "g_loss": math.nan, "d_loss": math.nan, "l1_train": math.nan, "val_l1": vl0}
        ]
        stopper = EarlyStopping(g, settings.patience, vl0 if np.isfinite(vl0) else math.inf)
        running, step = [], 0
        for step in range(1, settings.steps + 1):
            g.train()
            d.train()
            idx = torch.randint(0, n, (bs,), generator=gen)
            x, y = x_tr[idx], y_tr[idx]
            loss_g, loss_d, l1 = pix2pix_step(g, d, opt_g, opt_d, x, y, settings.lambda_l1)
            running.append((loss_g.item(), loss_d.item(), l1.item()))
            if step % settings.eval_every == 0 or step == settings.steps:
                gl, dl, l1m = (float(v) for v in np.mean(running, axis=0))
                vl = val_l1(g)
                curve.append(
                    {"step": step, "g_loss": gl, "d_loss": dl, "l1_train": l1m, "val_l1": vl}
                )
                running = []
                say(
                    f"step {step}/{settings.steps}: G loss {gl:.4f} D loss {dl:.4f} "
                    f"train L1 {l1m:.4f} val L1 {vl:.4f}"
                )
                if stopper.update(vl if np.isfinite(vl) else l1m, step, g):
                    break
    return Pix2PixFit.from_training(
        stopper.restore(g),
        stopper,
        curve,
        CURVE_COLUMNS,
        settings=settings,
        seed=seed,
        size=size,
        steps_run=step,
    )
