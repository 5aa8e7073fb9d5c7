"""Pixel generators' training steps and DDIM sampling against a GEMM and a conv roofline.

At the default settings (`Pix2PixSettings()`, `PixelDDPMSettings()` = config ``pixel``) on
the embedded default's frame size (config/config.yaml ``pixel.size``; `--size H,W` for
another), batch 32, for 1 and 2 torch threads:

- pix2pix step: `pix2pix.pix2pix_step` (G and D forward, backward, both Adam steps), what
  `fit_pix2pix` runs per step;
- DDPM step: `train.training_step` on the pixel U-Net (`ddpm.RowDenoiser`), fused AdamW and
  the EMA, what `fit_pixel_ddpm` runs per step;
- DDIM sampling: `sample_pixel_ddpm` at 10 steps, w = 1 (conditional pass only), frames/s.

Each is given as achieved GFLOP/s, with FLOPs counted by ``torch.utils.flop_counter
.FlopCounterMode`` over one call (convolutions and matrix products, forward and backward;
diffusers' mid-block attention over 48 tokens is not counted), and as a fraction of two
rooflines measured in the same run at the same thread count: one 1024^3 float32 torch.mm and
one large float32 conv2d (32 x 64 x 64 x 64 input, 64 3x3 filters). Times are the best of
several rounds (the machine is shared). No figure here is a pass/fail threshold.

    .venv/bin/python benchmarks/bench_pixel.py [--rounds 3] [--steps 10] [--rows 256] [--size H,W]

Run it under the environment of `tools/kernel_variants.py`'s ``avx2-2threads`` variant
(ATEN_CPU_CAPABILITY=avx2, ONEDNN_MAX_CPU_ISA=AVX2, ...) to see the same code on the kernels of
a CPU without AVX-512.
"""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path

import machine
import numpy as np
import torch
import torch.nn.functional as F
import yaml
from machine import best_of, parse_args, sized
from torch.utils.flop_counter import FlopCounterMode

from tacgen_lib.generate.pixel.ddpm import RowDenoiser, make_unet, sample_pixel_ddpm
from tacgen_lib.generate.pixel.pix2pix import (
    PatchDiscriminator,
    UNetTranslator,
    make_pix2pix_optimisers,
    pix2pix_step,
)
from tacgen_lib.generate.pixel.settings import Pix2PixSettings, PixelDDPMSettings, PixelSettings
from tacgen_lib.generate.schedules import make_schedule
from tacgen_lib.generate.train import make_optimiser, training_step

ROOT = Path(__file__).resolve().parents[1]
#: the generators' frame size: the embedded default's (`--size` replaces it)
SIZE = tuple(
    int(x) for x in yaml.safe_load((ROOT / "config/config.yaml").read_text())["pixel"]["size"]
)
BATCH = 32
#: the conv roofline's input (batch, channels = filters, side): a large float32 conv2d
CONV = sized((32, 64, 64), (4, 8, 16))


def lscpu_lines() -> list[str]:
    """The `lscpu` lines naming the CPU model and family."""
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return ["lscpu: not available"]
    keys = ("Model name", "CPU family", "Vendor ID")
    return [" ".join(line.split()) for line in out.splitlines() if line.startswith(keys)]


def flops_of(fn) -> float:
    """FLOPs torch's flop counter attributes to one call of `fn`."""
    with FlopCounterMode(display=False) as counter:
        fn()
    return float(counter.get_total_flops())


def mm_rate(n: int = 1024, reps: int = 5) -> float:
    """FLOP/s of one n^3 float32 torch.mm (best of `reps`)."""
    a, b = torch.randn(n, n), torch.randn(n, n)
    return 2 * n**3 / best_of(lambda: torch.mm(a, b), reps).wall


def conv_rate(reps: int = 3) -> float:
    """FLOP/s of one float32 conv2d (best of `reps`): `CONV` input, as many 3x3 filters as
    channels."""
    n, c, side = CONV
    x, w = torch.randn(n, c, side, side), torch.randn(c, c, 3, 3)
    flops = 2 * n * c * side * side * c * 9
    return flops / best_of(lambda: F.conv2d(x, w, padding=1), reps).wall


def toy_frames(n: int) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    rgb = torch.rand(n, 3, *SIZE, generator=g) * 2 - 1
    tac = torch.rand(n, 3, *SIZE, generator=g) - 0.5
    return rgb, tac


def pix2pix_bench(rounds: int, steps: int) -> tuple[float, float]:
    """(seconds per step, FLOPs per step) of `pix2pix_step` at the default settings."""
    s = Pix2PixSettings()
    torch.manual_seed(0)
    g, d = UNetTranslator(s.channels, s.dropout), PatchDiscriminator(s.disc_channels)
    opt_g, opt_d = make_pix2pix_optimisers(g, d, s)
    g.train()
    d.train()
    x, y = toy_frames(BATCH)

    def one() -> None:
        pix2pix_step(g, d, opt_g, opt_d, x, y, s.lambda_l1)

    flops = flops_of(one)
    t = min(best_of(lambda: [one() for _ in range(steps)], 1).wall for _ in range(rounds))
    return t / steps, flops


def ddpm_bench(rounds: int, steps: int) -> tuple[float, float]:
    """(seconds per step, FLOPs per step) of `training_step` on the default pixel U-Net."""
    s = PixelDDPMSettings()
    torch.manual_seed(0)
    unet = make_unet(s, SIZE)
    ema = make_unet(s, SIZE)
    ema.load_state_dict(unet.state_dict())
    ema.requires_grad_(False)
    model = RowDenoiser(unet, SIZE)
    opt = make_optimiser(list(unet.parameters()), s)
    ema_params = list(ema.parameters())
    sch = make_schedule(s.schedule, s.train_steps)
    sa = torch.from_numpy(np.sqrt(sch.alphas_cumprod)).float()
    s1 = torch.from_numpy(np.sqrt(sch.one_minus_alphas_cumprod)).float()
    rgb, tac = toy_frames(BATCH)
    x0, cond = tac.reshape(BATCH, -1), rgb.reshape(BATCH, -1)
    gen = torch.Generator().manual_seed(0)
    unet.train()

    def one() -> None:
        t = torch.randint(0, s.train_steps, (BATCH,), generator=gen)
        noise = torch.randn(BATCH, x0.shape[1], generator=gen)
        drop = torch.rand(BATCH, generator=gen) < s.p_uncond
        training_step(model, opt, ema_params, (x0, cond, t, noise, drop), sa, s1, s)

    flops = flops_of(one)
    t = min(best_of(lambda: [one() for _ in range(steps)], 1).wall for _ in range(rounds))
    return t / steps, flops


def sampling_bench(rounds: int, rows: int) -> tuple[float, float]:
    """(seconds, FLOPs) of DDIM-10 at w = 1 over `rows` frames with the default U-Net."""
    s = PixelDDPMSettings()
    torch.manual_seed(0)
    unet = make_unet(s, SIZE).eval()
    rgb = toy_frames(rows)[0].numpy()
    kw = {
        "schedule": make_schedule(s.schedule, s.train_steps),
        "prediction": s.prediction,
        "steps": 10,
        "guidance": 1.0,
        "eta": 0.0,
        "seed": 0,
        "batch": PixelSettings.batch,
    }

    def run() -> None:
        sample_pixel_ddpm(unet, rgb, **kw)

    flops = flops_of(run)
    return best_of(run, rounds).wall, flops


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=10, help="training steps per timed round")
    ap.add_argument("--rows", type=int, default=256, help="frames sampled (DDIM-10, w = 1)")
    ap.add_argument("--threads", default="1,2", help="torch thread counts, comma-separated")
    ap.add_argument("--size", default=None, help="frame size H,W (default: pixel.size)")
    tiny = {"rounds": 1, "steps": 1, "rows": 2, "threads": "1", "size": "8,16"}
    args = parse_args(ap, tiny)
    if args.size:
        global SIZE
        SIZE = tuple(int(x) for x in args.size.split(","))
    for line in lscpu_lines():
        print(line)
    print(machine.describe())
    print(f"frames {SIZE[0]}x{SIZE[1]}, batch {BATCH}; default pixel.pix2pix and pixel.ddpm")
    for threads in (int(t) for t in args.threads.split(",")):
        torch.set_num_threads(threads)
        mm, conv = mm_rate(), conv_rate()
        p_s, p_f = pix2pix_bench(args.rounds, args.steps)
        d_s, d_f = ddpm_bench(args.rounds, args.steps)
        s_s, s_f = sampling_bench(args.rounds, args.rows)
        mm, conv = max(mm, mm_rate()), max(conv, conv_rate())
        print(
            f"\n-- {threads} thread(s): torch.mm 1024^3 {mm / 1e9:.1f} GFLOP/s, "
            f"conv2d {CONV[0]}x{CONV[1]}x{CONV[2]}x{CONV[2]} 3x3 {conv / 1e9:.1f} GFLOP/s"
        )

        for name, seconds, flops, extra in (
            ("pix2pix G+D step", p_s, p_f, f"{p_s * 1e3:.1f} ms/step"),
            ("DDPM step", d_s, d_f, f"{d_s * 1e3:.1f} ms/step"),
            (
                f"DDIM-10 w=1, {args.rows} frames",
                s_s,
                s_f,
                f"{s_s:.2f} s, {args.rows / s_s:.0f} frames/s",
            ),
        ):
            rate = flops / seconds
            print(
                f"{name}: {extra}; {flops / 1e9:.3f} GFLOP -> {rate / 1e9:.2f} GFLOP/s = "
                f"{rate / mm:.2f} of mm, {rate / conv:.2f} of conv"
            )


if __name__ == "__main__":
    main()
