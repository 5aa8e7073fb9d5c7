"""Training the latent generator: the denoising objective, AdamW + EMA, early stopping, save/load.

This module owns `fit_generator` (one generator per corpus x seed, on the train split's V -> T
pairs, early-stopped on the val split's loss), the EMA training every diffusion generator shares
(`train_ema`, the pixel DDPM's too), its objective `diffusion_loss` and the hashed
weights file (`save_generator` / `load_generator`: EMA weights, the train-split standardisation
statistics, the settings and the curve in one file with a sidecar, like the alignment heads).

Bit-reproducible on one machine: the initial weights come from torch.manual_seed(seed), every
random draw of training (batches, timesteps, noise, condition drops) from one torch.Generator
seeded with `seed`, validation noise from a second generator seeded with seed + 1.
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from tacgen_lib.generate.inference import (
    GeneratorRecord,
    GeneratorWeights,
    encode_generator,
    fit_standardiser,
    read_generator,
)
from tacgen_lib.generate.model import Denoiser
from tacgen_lib.generate.schedules import make_schedule
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.generate.stopping import EarlyStopping
from tacgen_lib.io import hashed
from tacgen_lib.optim import AdamW

__all__ = [
    "EMATraining",
    "GeneratorFit",
    "ValidationDraws",
    "diffusion_loss",
    "fit_generator",
    "load_generator",
    "make_optimiser",
    "run_training_steps",
    "save_generator",
    "train_ema",
    "training_step",
]

#: Validation rows are cut into batches of this many (the loss is a row mean either way).
_VAL_REPEATS = 4


def diffusion_loss(
    model: Denoiser,
    x0: Tensor,
    cond: Tensor,
    t: Tensor,
    noise: Tensor,
    drop: Tensor | None,
    sqrt_abar: Tensor,
    sqrt_1m_abar: Tensor,
    prediction: str,
) -> Tensor:
    """Simple DDPM loss (Ho et al. 2020, eq. 14), eps- or v-target.

    1. x_t = sqrt(abar_t) x0 + sqrt(1 - abar_t) eps   (DDPM eq. 4)
    2. target: eps, or v = sqrt(abar_t) eps - sqrt(1 - abar_t) x0 (Salimans & Ho 2022)
    3. mean squared error of the model output against the target
    """
    a, s = sqrt_abar[t][:, None], sqrt_1m_abar[t][:, None]
    x_t = a * x0 + s * noise
    target = noise if prediction == "eps" else a * noise - s * x0
    return torch.mean((model(x_t, t, cond, drop) - target) ** 2)


def make_optimiser(params: list[Tensor], settings: GenerateSettings) -> AdamW:
    """AdamW over `params` with torch's fused kernel (one pass per parameter tensor per step,
    not the ~10 elementwise passes of the default CPU loop; deterministic on CPU), through
    `tacgen_lib.optim` (no torch._dynamo import)."""
    return AdamW(params, lr=settings.lr, weight_decay=settings.weight_decay, fused=True)


def training_step(
    model: Denoiser,
    opt: AdamW,
    ema_params: list[Tensor],
    batch: tuple[Tensor, Tensor, Tensor, Tensor, Tensor | None],
    sqrt_abar: Tensor,
    sqrt_1m_abar: Tensor,
    settings: GenerateSettings,
) -> Tensor:
    """One optimiser step on `batch` = (x0, cond, t, noise, drop); returns the loss.

    1. the denoising loss (`diffusion_loss`) and its gradient
    2. gradient norm clipped at ``clip_grad`` (one fused norm over all parameters)
    3. AdamW step, then the EMA: ema <- ema + (1 - ema_decay) (param - ema)
    """
    params = [p for group in opt.param_groups for p in group["params"]]
    loss = diffusion_loss(model, *batch, sqrt_abar, sqrt_1m_abar, settings.prediction)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    if settings.clip_grad > 0:
        torch.nn.utils.clip_grad_norm_(params, settings.clip_grad, foreach=True)
    opt.step()
    with torch.no_grad():
        torch._foreach_lerp_(ema_params, params, 1.0 - settings.ema_decay)
    return loss


def run_training_steps(
    model: nn.Module,
    opt: AdamW,
    ema: nn.Module,
    train: tuple[Tensor, Tensor],
    schedule: tuple[Tensor, Tensor],
    settings: Any,
    *,
    gen: torch.Generator,
    val_loss: Callable[[], float],
    stopper: EarlyStopping,
    curve: list[dict],
    progress: Callable[[str], Any],
) -> int:
    """The minibatch loop every diffusion generator trains with (the latent generator here, the
    pixel DDPM in `tacgen_lib.generate.pixel.ddpm`); returns the last step run.

    Per step: ``batch_size`` train pairs (x0, cond) drawn with replacement, t uniform in
    0..T-1, eps ~ N(0, I) and the condition dropped with probability ``p_uncond``, all from
    `gen` in that order; then `training_step` (loss, clipping, AdamW, the EMA of `ema`). Every
    ``eval_every`` steps and at the last: `val_loss` of the EMA model, one row appended to
    `curve` (step, mean train loss since the last row, val loss), and `stopper` told the val
    loss (the train loss where there are no val rows); training ends when it says so.
    `schedule`: (sqrt(abar_t), sqrt(1 - abar_t)) over the T steps. The draws come from `gen`
    on the CPU and move to the device of the train tensors (on the CPU: no move), so a GPU
    run draws the same numbers.
    """
    x_tr, c_tr = train
    sqrt_abar, sqrt_1m = schedule
    dev = x_tr.device
    n, T = x_tr.shape[0], sqrt_abar.shape[0]
    bs = min(settings.batch_size, n)
    ema_params = list(ema.parameters())
    running: list[float] = []
    step = 0
    for step in range(1, settings.steps + 1):
        model.train()
        idx = torch.randint(0, n, (bs,), generator=gen)
        t = torch.randint(0, T, (bs,), generator=gen)
        noise = torch.randn(bs, x_tr.shape[1], generator=gen)
        drop = torch.rand(bs, generator=gen) < settings.p_uncond
        t, noise, drop = t.to(dev), noise.to(dev), drop.to(dev)
        loss = training_step(
            model,
            opt,
            ema_params,
            (x_tr[idx], c_tr[idx], t, noise, drop),
            sqrt_abar,
            sqrt_1m,
            settings,
        )
        running.append(loss.item())
        if step % settings.eval_every == 0 or step == settings.steps:
            vl = val_loss()
            curve.append({"step": step, "train_loss": float(np.mean(running)), "val_loss": vl})
            running = []
            progress(
                f"step {step}/{settings.steps}: train loss {curve[-1]['train_loss']:.4f} "
                f"val loss {vl:.4f}"
            )
            score = vl if np.isfinite(vl) else curve[-1]["train_loss"]
            if stopper.update(score, step, ema):
                break
    return step


@dataclass(frozen=True)
class ValidationDraws:
    """What every evaluation of a fit scores: the val rows (x0, cond) and, per repeat, the same
    timesteps ``t`` (repeats, n) and noise (repeats, n, d), drawn once from a generator seeded
    with seed + 1; the schedule's (sqrt(abar_t), sqrt(1 - abar_t)) and the target."""

    x: Tensor
    cond: Tensor
    t: Tensor
    noise: Tensor
    sqrt_abar: Tensor
    sqrt_1m: Tensor
    prediction: str

    def loss(self, model: nn.Module, r: int, rows: slice = slice(None)) -> Tensor:
        """`diffusion_loss` of `model` on repeat r's draws of `rows` (no condition dropped)."""
        return diffusion_loss(
            model,
            self.x[rows],
            self.cond[rows],
            self.t[r, rows],
            self.noise[r, rows],
            None,
            self.sqrt_abar,
            self.sqrt_1m,
            self.prediction,
        )


@dataclass(frozen=True)
class EMATraining:
    """A finished `train_ema`: the EMA module with its best state (eval mode, on the CPU), the
    `EarlyStopping` that chose it, the last step run and the curve's rows."""

    ema: nn.Module
    stopper: EarlyStopping
    steps_run: int
    curve: list[dict]


def train_ema(
    net: nn.Module,
    train: tuple[Tensor, Tensor],
    val: tuple[Tensor, Tensor],
    settings: Any,
    seed: int,
    device: torch.device | str,
    *,
    val_loss: Callable[[nn.Module, ValidationDraws], float],
    wrap: Callable[[nn.Module], nn.Module] = lambda m: m,
    score_untrained: bool = False,
    progress: Callable[[str], Any],
) -> EMATraining:
    """Train an initialised denoiser `net` with an EMA copy, early-stopped on validation: the
    training every diffusion generator shares (`fit_generator`, the pixel DDPM's
    `tacgen_lib.generate.pixel.ddpm.fit_pixel_ddpm`).

    1. the schedule of ``settings`` (``schedule``, ``train_steps``), the EMA copy of `net`, all
       moved to `device` (on the CPU no move); AdamW (`make_optimiser`) over `net`
    2. `ValidationDraws` of the val rows (`_VAL_REPEATS` repeats, from seed + 1)
    3. `score_untrained`: the untrained EMA model scored as curve row step 0 (train loss NaN)
       and the stopper's starting score; else the stopper starts at infinity
    4. `run_training_steps` (draws from a generator seeded with `seed`), then the EMA copy with
       its best state (`EarlyStopping.restore`)

    `wrap` turns a module into what `diffusion_loss` calls (the pixel DDPM's rows view of its
    U-Net); `val_loss` scores the wrapped EMA model on the draws.
    """
    schedule = make_schedule(settings.schedule, settings.train_steps)
    sqrt_abar = torch.from_numpy(np.sqrt(schedule.alphas_cumprod)).float()
    sqrt_1m = torch.from_numpy(np.sqrt(schedule.one_minus_alphas_cumprod)).float()
    ema = copy.deepcopy(net)
    ema.requires_grad_(False)
    dev = torch.device(device)  # on the CPU every `.to` below is no move
    net.to(dev)
    ema.to(dev)
    x_tr, c_tr, x_va, c_va = (a.to(dev) for a in (*train, *val))
    sqrt_abar, sqrt_1m = sqrt_abar.to(dev), sqrt_1m.to(dev)
    model, ema_model = wrap(net), wrap(ema)
    opt = make_optimiser(list(net.parameters()), settings)
    gen = torch.Generator().manual_seed(int(seed))
    # Fixed validation draws: every evaluation scores the same (t, noise) for each val row.
    vgen = torch.Generator().manual_seed(int(seed) + 1)
    n_va = x_va.shape[0]
    val_t = torch.randint(0, schedule.n_steps, (_VAL_REPEATS, n_va), generator=vgen).to(dev)
    val_noise = torch.randn(_VAL_REPEATS, n_va, x_tr.shape[1], generator=vgen).to(dev)
    draws = ValidationDraws(x_va, c_va, val_t, val_noise, sqrt_abar, sqrt_1m, settings.prediction)

    def validate() -> float:
        return val_loss(ema_model, draws)

    curve: list[dict] = []
    start = math.inf
    if score_untrained:
        vl0 = validate()
        curve.append({"step": 0, "train_loss": math.nan, "val_loss": vl0})
        start = vl0 if np.isfinite(vl0) else math.inf
    stopper = EarlyStopping(ema, settings.patience, start)
    step = run_training_steps(
        model,
        opt,
        ema,
        (x_tr, c_tr),
        (sqrt_abar, sqrt_1m),
        settings,
        gen=gen,
        val_loss=validate,
        stopper=stopper,
        curve=curve,
        progress=progress,
    )
    return EMATraining(stopper.restore(ema), stopper, step, curve)


@dataclass(frozen=True)
class GeneratorFit(GeneratorRecord):
    """A trained generator with its torch EMA denoiser (eval mode), for training-side use."""

    model: Denoiser = field(kw_only=True)

    def weights(self) -> GeneratorWeights:
        """The fit as sampling reads it (numpy arrays of the EMA weights; no torch)."""
        return GeneratorWeights(**self.record(), denoiser=self.model.arrays())


def _as_f32(x: np.ndarray, name: str) -> Tensor:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != 2 or not np.isfinite(arr).all():
        raise ValueError(f"{name}: expected a finite (n, d) array, got shape {arr.shape}")
    return torch.from_numpy(arr.astype(np.float32))


def _val_loss(ema: nn.Module, draws: ValidationDraws) -> float:
    """The mean over repeats of the loss on all val rows at once (NaN without val rows)."""
    if draws.x.shape[0] == 0:
        return float("nan")
    ema.eval()
    with torch.no_grad():
        losses = [draws.loss(ema, r).item() for r in range(_VAL_REPEATS)]
    return float(np.mean(losses))


def fit_generator(
    t_train: np.ndarray,
    v_train: np.ndarray,
    t_val: np.ndarray,
    v_val: np.ndarray,
    settings: GenerateSettings,
    *,
    seed: int,
    progress: Callable[[str], Any] | None = None,
    device: torch.device | str,
) -> GeneratorFit:
    """Train the eps- (or v-) prediction denoiser on train pairs, early-stopped on val pairs.

    t_*: real tactile features (n, d_t), v_*: vision features (n, d_v), row i a pair. The
    tactile features are standardised with the train rows' statistics (`fit_standardiser`).
    Returns the EMA weights of the evaluation with the lowest validation loss (on the CPU).
    device: where it trains (`tacgen_lib.runtime.device`); the weights are initialised and
    every random draw made on the CPU, so only the arithmetic moves (none on the CPU).
    """
    say = progress or (lambda _m: None)
    if len(t_train) != len(v_train) or len(t_val) != len(v_val):
        raise ValueError("fit_generator: tactile and vision rows differ in number")
    if len(t_train) < 2:
        raise ValueError(f"fit_generator: need >= 2 train rows, got {len(t_train)}")
    std = fit_standardiser(t_train)
    x_tr = _as_f32(std.forward(t_train), "t_train")
    c_tr = _as_f32(v_train, "v_train")
    x_va = _as_f32(std.forward(t_val), "t_val") if len(t_val) else x_tr[:0]
    c_va = _as_f32(v_val, "v_val") if len(v_val) else c_tr[:0]
    torch.manual_seed(int(seed))
    model = Denoiser(
        x_tr.shape[1], c_tr.shape[1], settings.hidden, settings.blocks, settings.time_dim
    )
    pairs = (x_tr, c_tr), (x_va, c_va)
    fit = train_ema(model, *pairs, settings, seed, device, val_loss=_val_loss, progress=say)
    stopper = fit.stopper
    return GeneratorFit(
        std,
        settings,
        int(seed),
        fit.curve,
        stopper.step,
        stopper.score,
        fit.steps_run,
        stopper.stopped,
        model=fit.ema,
    )


def save_generator(fit: GeneratorFit, path: str | os.PathLike[str], *, producer: str = "") -> str:
    """Write EMA weights + standardisation statistics + settings + curve atomically, with a
    sidecar hash (`hashed.write_bytes`); the bytes depend only on the fit. Returns SHA-256."""
    d = fit.model.dims
    return hashed.write_bytes(
        path,
        encode_generator(fit.weights()),
        rows=1,
        key="generator",
        columns={
            "denoiser": f"residual mlp {d['dim_t']}+{d['dim_v']} -> "
            f"{d['blocks']} x {d['hidden']} -> {d['dim_t']}"
        },
        vectors={},
        producer=producer,
    )


def load_generator(path: str | os.PathLike[str], *, verify: bool = True) -> GeneratorFit:
    """A generator written by `save_generator` (its hash checked first), with its torch model;
    sampling reads the same file without torch (`inference.read_generator`)."""
    w = read_generator(path, verify=verify)
    d = w.denoiser.dims
    model = Denoiser(d["dim_t"], d["dim_v"], d["hidden"], d["blocks"], d["time_dim"])
    model.load_state_dict({k: torch.from_numpy(v) for k, v in w.denoiser.params.items()})
    model.eval()
    return GeneratorFit(**w.record(), model=model)
