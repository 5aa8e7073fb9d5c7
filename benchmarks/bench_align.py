"""Head-training throughput against the machine's float32 GEMM roofline (same run).

For in_dim 384 and 768 (ViT-S / ViT-B feature widths) and batch 256, this times
`tacgen_lib.align.train.train_step` (forward of both heads, symmetric InfoNCE, backward, clipping,
fused AdamW) and compares it with the time the same step's matrix products would take at the
float32 GEMM rate torch.matmul reaches on this machine, measured in the same process,
interleaved with the step timings (so both see the same load):

    roofline time = FLOPs(forward + backward of the two MLPs and the logits) / GEMM FLOP/s
    fraction      = roofline time / measured step time           (target >= 0.5)

FLOPs of one step, per head (B = batch, d = in_dim, h = 512, o = 128):
forward 2B(dh + ho); backward 2B·dh (fc1 weight grad; the frozen features need no input grad)
+ 4B·ho (fc2 weight and input grads). Logits: 2B²o forward, 4B²o backward.

It also runs `fit_heads` end to end (evaluations included) and projects the wall time of one
paper-budget grid cell (6,000 steps). The machine is shared, so each figure is the best of
several rounds (and the median is printed too), and the ratio is also given with process
CPU seconds in place of wall seconds for both sides (`cpu-frac`), which is much less
sensitive to other processes competing for the cores.

    .venv/bin/python benchmarks/bench_align.py [--rounds 5] [--steps 20] [--threads N]
"""

from __future__ import annotations

import argparse
import math
import statistics

import machine
import numpy as np
import torch
from machine import Timing, best_of, gemm_peak, parse_args, sized

from tacgen_lib.align.heads import HIDDEN_DIM, OUT_DIM, AlignHeads
from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.align.train import fit_heads, make_optimizer, train_step

PAPER_STEPS = 6000
BATCH = 256
#: training pairs the timed steps draw their batches from (the fit's validation: a quarter)
PAIRS = sized(4096, 2 * BATCH)


def step_flops(batch: int, in_dim_v: int, in_dim_t: int) -> float:
    """Matrix-product FLOPs of one training step (forward + backward), see module docstring."""
    h, o = HIDDEN_DIM, OUT_DIM
    total = 0.0
    for d in (in_dim_v, in_dim_t):
        total += 2 * batch * (d * h + h * o)  # forward
        total += 2 * batch * d * h + 4 * batch * h * o  # backward
    total += 2 * batch * batch * o * 3  # logits forward + 2 backward products
    return total


def gemm_only(batch: int, in_dim: int, reps: int = 5) -> Timing:
    """Time of just the step's matrix products at their own shapes (best of `reps`).

    The same GEMMs the step runs (per head: fc1 and fc2 forward, fc1 weight grad, fc2 weight
    and input grads; logits forward and its two backward products), with nothing else: the
    best a step could do at these small shapes on this machine.
    """
    h, o = HIDDEN_DIM, OUT_DIM
    x, w1, a1 = torch.randn(batch, in_dim), torch.randn(h, in_dim), torch.randn(batch, h)
    w2, g2, z = torch.randn(o, h), torch.randn(batch, o), torch.randn(batch, o)
    g_logits = torch.randn(batch, batch)

    def products() -> None:
        for _ in range(2):  # two heads
            x @ w1.T  # fc1 forward
            a1 @ w2.T  # fc2 forward
            g2 @ w2  # fc2 input grad
            g2.T @ a1  # fc2 weight grad
            a1.T @ x  # fc1 weight grad
        z @ z.T  # logits
        g_logits @ z  # logits grads (two products)
        g_logits.T @ z

    return best_of(products, reps)


def time_steps(in_dim: int, steps: int, rounds: int) -> tuple[Timing, Timing, list[float]]:
    """Best per-step time of `train_step`, best 1024^3 GEMM time (measured between the rounds),
    and the per-round wall seconds per step (for the median)."""
    torch.manual_seed(0)
    n = PAIRS
    v, t = torch.randn(n, in_dim), torch.randn(n, in_dim)
    heads = AlignHeads(in_dim, in_dim).train()
    opt = make_optimizer(heads, lr=1e-4, weight_decay=0.01)
    order = torch.from_numpy(np.random.default_rng(0).permutation(n))

    def run() -> None:
        for i in range(steps):
            lo = (i * BATCH) % (n - BATCH)
            ix = order[lo : lo + BATCH]
            train_step(heads, opt, v[ix], t[ix], tau=0.07, lr=1e-4, clip_grad=1.0)

    run()  # warm-up
    step_best, gemm_best, walls = Timing(math.inf, math.inf), Timing(math.inf, math.inf), []
    for _ in range(rounds):
        gemm_best = gemm_best.min(gemm_peak())
        one = best_of(run, 1)
        walls.append(one.wall / steps)
        step_best = step_best.min(Timing(one.wall / steps, one.cpu / steps))
    gemm_best = gemm_best.min(gemm_peak())
    return step_best, gemm_best, walls


def time_fit(in_dim: int, steps: int) -> float:
    """Seconds per step of fit_heads end to end (eval every 50 steps on PAIRS // 4 val pairs)."""
    rng = np.random.default_rng(0)
    n_train, n_val = PAIRS, PAIRS // 4
    v = rng.standard_normal((n_train + n_val, in_dim)).astype(np.float32)
    t = rng.standard_normal((n_train + n_val, in_dim)).astype(np.float32)
    res = fit_heads(
        v,
        t,
        np.arange(n_train),
        np.arange(n_train, n_train + n_val),
        tau=0.07,
        seed=0,
        settings=AlignSettings(
            budget="steps", steps=steps, batch_size=BATCH, patience=0, eval_every=50
        ),
        device="cpu",
    )
    return res.seconds / steps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=20, help="steps per timed round")
    ap.add_argument("--fit-steps", type=int, default=100, help="steps of the end-to-end fit")
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0 = torch default)")
    args = parse_args(ap, {"rounds": 1, "steps": 2, "fit_steps": 2, "threads": 1})
    if args.threads:
        torch.set_num_threads(args.threads)
    print(f"machine: {machine.describe()}")
    print(f"torch {torch.__version__}, threads {torch.get_num_threads()}, batch {BATCH}")
    head = (
        f"{'in_dim':>6} {'GEMM GF/s':>9} {'GF/step':>7} {'ms/step':>8} {'median':>7} "
        f"{'samples/s':>9} {'roofline':>8} {'fraction':>8} {'cpu-frac':>8} {'target':>6} "
        f"{'mm-only':>7} {'fit ms/step':>11} {'6000 steps':>10}"
    )
    print(head)
    for in_dim in (384, 768):
        step, gemm, walls = time_steps(in_dim, args.steps, args.rounds)
        flops = step_flops(BATCH, in_dim, in_dim)
        peak_flops = 2 * 1024**3
        roofline = Timing(flops * gemm.wall / peak_flops, flops * gemm.cpu / peak_flops)
        fraction = roofline.wall / step.wall
        cpu_fraction = roofline.cpu / step.cpu
        mm_only = gemm_only(BATCH, in_dim)
        fit_s = time_fit(in_dim, args.fit_steps)
        print(
            f"{in_dim:>6} {peak_flops / gemm.wall / 1e9:>9.1f} {flops / 1e9:>7.3f} "
            f"{step.wall * 1e3:>8.2f} {statistics.median(walls) * 1e3:>7.2f} "
            f"{BATCH / step.wall:>9.0f} {BATCH / roofline.wall:>8.0f} {fraction:>8.2f} "
            f"{cpu_fraction:>8.2f} {'ok' if fraction >= 0.5 else 'BELOW':>6} "
            f"{mm_only.wall * 1e3:>7.2f} {fit_s * 1e3:>11.2f} {PAPER_STEPS * fit_s:>9.1f}s"
        )
    print(
        "fraction = (step FLOPs / best 1024^3 GEMM FLOP/s) / best measured step wall time; "
        "cpu-frac = the same with process CPU seconds for both (less sensitive to other "
        "processes on a shared machine); roofline in samples/s; mm-only = ms of just the "
        "step's GEMMs at their own small shapes; '6000 steps' = projected wall time of one "
        "paper-budget cell from the end-to-end fit_heads rate (evaluations included)."
    )


if __name__ == "__main__":
    main()
