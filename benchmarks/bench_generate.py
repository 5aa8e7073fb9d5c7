"""Generator training and sampling throughput against the float32 GEMM roofline (same run).

Training: one optimiser step of `tacgen_lib.generate.train` (`training_step`, the function
`fit_generator` runs) at the default size (`GenerateSettings`' defaults = config ``generate``:
blocks x hidden residual MLP on 192-d ViT-tiny features, batch_size rows) -- forward, the
denoising loss, backward, clipping, fused AdamW and the EMA update -- against the time its
matrix products would take at the float32 GEMM rate of one 1024^3 torch.matmul measured in the
same process between the rounds:

    FLOPs of a step = sum over Linear layers of 2 B in out (forward) + 2 B in out (weight grad)
                      + 2 B in out (input grad, except layers fed by data: inp, cond[0], time[0])
    fraction        = (FLOPs / GEMM FLOP/s) / measured step seconds      (issue target >= 0.5)

Sampling: DDIM-50 with classifier-free guidance (conditional and unconditional rows in one
batch of 2n) over n = 1,200 rows, in numpy (`inference.DenoiserArrays`, what a sample_generator
job runs): generated vectors per second and the roofline fraction over the FLOPs `sample`
performs (`sample_flops`: the condition's share of the embeddings once per batch, the time MLP
on one row per step; the FLOPs a plain forward per step would need are printed too, as
"forward-equivalent"), against one 1024^3 float32 numpy matmul (numpy's BLAS, which sampling
uses). Then what one sampling job pays before it samples: the seconds a fresh interpreter takes
to import the sampling job's modules, against importing torch (which those modules avoid). The machine is shared: each figure is the best of several rounds, and the
ratio is also given with process CPU seconds (`cpu-frac`), less sensitive to competing load.

    .venv/bin/python benchmarks/bench_generate.py [--rounds 5] [--steps 30] [--threads N]
        [--hidden 256 --blocks 3 --dim 192 --batch 128]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

import machine
import numpy as np
import torch
from machine import best_of, gemm_peak, parse_args, sized
from threadpoolctl import threadpool_limits
from torch import nn

from tacgen_lib.generate.model import Denoiser
from tacgen_lib.generate.sampling import sample
from tacgen_lib.generate.schedules import make_schedule
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.generate.train import make_optimiser, training_step


def linear_shapes(model: Denoiser) -> list[tuple[str, int, int]]:
    return [
        (n, m.in_features, m.out_features)
        for n, m in model.named_modules()
        if isinstance(m, nn.Linear)
    ]


def step_flops(model: Denoiser, batch: int) -> float:
    """Matrix-product FLOPs of one training step (see module docstring)."""
    total = 0.0
    for name, i, o in linear_shapes(model):
        total += 4 * batch * i * o  # forward + weight grad
        if name not in ("inp", "cond.0", "time.0"):
            total += 2 * batch * i * o  # input grad
    return total


def forward_flops(model: Denoiser, batch: int) -> float:
    return sum(2 * batch * i * o for _, i, o in linear_shapes(model))


def sample_flops(model: Denoiser, rows: int, steps: int) -> float:
    """Matrix-product FLOPs of `sampling.sample` with CFG over `rows` (batch 2 rows): once per
    batch the condition MLP and each block's embedding projection on 2 rows rows; per step the
    time MLP and the blocks' time projections on one row, everything else on 2 rows rows."""
    total = 0.0
    for name, i, o in linear_shapes(model):
        if name.startswith("cond."):
            total += 2 * (2 * rows) * i * o
        elif name.startswith("time.") or name.endswith(".emb"):
            total += steps * 2 * i * o + (2 * 2 * rows * i * o if name.endswith(".emb") else 0)
        else:
            total += steps * 2 * (2 * rows) * i * o
    return total


def gemm_rate(n: int = 1024) -> tuple[float, float]:
    """FLOP/s of one n^3 float32 matmul by wall and by process CPU seconds (best of 5)."""
    wall, cpu = gemm_peak(n)
    return 2 * n**3 / wall, 2 * n**3 / cpu


def numpy_gemm_rate(n: int = 1024) -> tuple[float, float]:
    """FLOP/s of one n^3 float32 numpy matmul by wall and by process CPU seconds (best of 5)."""
    rng = np.random.default_rng(0)
    a = rng.standard_normal((n, n), dtype=np.float32)
    b = rng.standard_normal((n, n), dtype=np.float32)
    wall, cpu = best_of(lambda: a @ b, 5)
    return 2 * n**3 / wall, 2 * n**3 / cpu


def import_seconds(modules: str, reps: int = sized(3, 1)) -> float:
    """Best wall seconds of a fresh interpreter importing `modules` (minus a bare start)."""

    def run(code: str) -> float:
        best = float("inf")
        for _ in range(reps):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-c", code], check=True)
            best = min(best, time.perf_counter() - t0)
        return best

    return run(f"import {modules}") - run("pass")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--hidden", type=int, default=GenerateSettings.hidden)
    ap.add_argument("--blocks", type=int, default=GenerateSettings.blocks)
    ap.add_argument("--dim", type=int, default=192, help="d_t = d_v (ViT-tiny: 192)")
    ap.add_argument("--batch", type=int, default=GenerateSettings.batch_size)
    ap.add_argument("--rows", type=int, default=1200, help="rows sampled (DDIM-50, CFG)")
    tiny = {"rounds": 1, "steps": 2, "threads": 1, "hidden": 16, "blocks": 1, "dim": 8}
    args = parse_args(ap, {**tiny, "batch": 8, "rows": 16})
    torch.set_num_threads(args.threads)
    print(machine.describe())
    print(
        f"threads {args.threads}; model {args.blocks} x {args.hidden}, d {args.dim}, "
        f"batch {args.batch}"
    )

    torch.manual_seed(0)
    s = GenerateSettings(
        hidden=args.hidden, blocks=args.blocks, batch_size=args.batch, prediction="v"
    )
    model = Denoiser(args.dim, args.dim, args.hidden, args.blocks, s.time_dim)
    ema = Denoiser(args.dim, args.dim, args.hidden, args.blocks, s.time_dim)
    ema.load_state_dict(model.state_dict())
    ema.requires_grad_(False)
    params, ema_params = list(model.parameters()), list(ema.parameters())
    opt = make_optimiser(params, s)
    sch = make_schedule("cosine", 1000)
    sa = torch.from_numpy(np.sqrt(sch.alphas_cumprod)).float()
    s1 = torch.from_numpy(np.sqrt(sch.one_minus_alphas_cumprod)).float()
    n = 4096
    x0, cond = torch.randn(n, args.dim), torch.randn(n, args.dim)
    gen = torch.Generator().manual_seed(0)

    def steps() -> None:
        for _ in range(args.steps):
            idx = torch.randint(0, n, (args.batch,), generator=gen)
            t = torch.randint(0, 1000, (args.batch,), generator=gen)
            noise = torch.randn(args.batch, args.dim, generator=gen)
            drop = torch.rand(args.batch, generator=gen) < s.p_uncond
            training_step(model, opt, ema_params, (x0[idx], cond[idx], t, noise, drop), sa, s1, s)

    flops = step_flops(model, args.batch)
    step_w, step_c, rate_w, rate_c = float("inf"), float("inf"), 0.0, 0.0
    for _ in range(args.rounds):
        rw, rc = gemm_rate()
        rate_w, rate_c = max(rate_w, rw), max(rate_c, rc)
        w, c = best_of(steps, 1)
        step_w, step_c = min(step_w, w / args.steps), min(step_c, c / args.steps)
    rw, rc = gemm_rate()
    rate_w, rate_c = max(rate_w, rw), max(rate_c, rc)
    print(f"GEMM 1024^3: {rate_w / 1e9:.1f} GF/s wall, {rate_c / 1e9:.1f} GF/s per CPU second")
    print(
        f"training step: {step_w * 1e3:.2f} ms ({flops / 1e9:.3f} GFLOP); roofline fraction "
        f"{flops / rate_w / step_w:.2f} (cpu-frac {flops / rate_c / step_c:.2f}); "
        f"{1 / step_w:.0f} steps/s"
    )

    arrays = ema.arrays()
    rows = np.random.default_rng(0).standard_normal((args.rows, args.dim)).astype(np.float32)
    kw = {"sampler": "ddim", "steps": 50, "guidance": 2.0, "seed": 0, "prediction": "v"}
    kw |= {"eta": s.eta, "batch": s.batch}
    with threadpool_limits(args.threads):
        np_w, np_c = numpy_gemm_rate()
        sw, sc = best_of(lambda: sample(arrays, sch, rows, **kw), max(1, args.rounds // 2))
        rw, rc = numpy_gemm_rate()
    np_w, np_c = max(np_w, rw), max(np_c, rc)
    f_sample = sample_flops(model, args.rows, 50)
    f_plain = 50 * forward_flops(model, 2 * args.rows)
    print(f"numpy GEMM 1024^3: {np_w / 1e9:.1f} GF/s wall, {np_c / 1e9:.1f} GF/s per CPU second")
    print(
        f"sampling DDIM-50 + CFG (numpy), {args.rows} rows: {sw:.2f} s, "
        f"{args.rows / sw:.0f} vectors/s; roofline fraction {f_sample / np_w / sw:.2f} "
        f"(cpu-frac {f_sample / np_c / sc:.2f}) on {f_sample / 1e9:.1f} GFLOP performed; "
        f"forward-equivalent {f_plain / np_w / sw:.2f} ({f_plain / 1e9:.1f} GFLOP)"
    )
    job = import_seconds(
        "tacgen_lib.generate.inference, tacgen_lib.generate.sampling, "
        "tacgen_lib.io.edges, tacgen_lib.io.log, pandas"
    )
    with_torch = import_seconds("torch")
    print(
        f"per sampling job, before sampling: its imports {job:.2f} s; importing torch "
        f"{with_torch:.2f} s more would be {with_torch / max(job, 1e-9):.1f}x that"
    )


if __name__ == "__main__":
    main()
