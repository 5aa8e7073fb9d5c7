"""Tests of tacgen_lib.align (heads, loss, train, checkpoint): heads, symmetric InfoNCE (paper eq. 1) and head training.

Hard cases are checked against `info_nce_reference` (float64, plain loops, no cross_entropy or
matmul) and against a float64 copy of the heads.
"""

from __future__ import annotations

import copy
import io
import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from hypothesis import given, settings
from hypothesis import strategies as st
from rounding import reordered_sum_atol
from scipy.stats import binom

from tacgen_lib.align import checkpoint as align_checkpoint
from tacgen_lib.align import heads as align_heads
from tacgen_lib.align.checkpoint import load_heads, save_heads
from tacgen_lib.align.heads import AlignHeads, l2_normalise, project
from tacgen_lib.align.loss import info_nce, info_nce_reference
from tacgen_lib.align.retrieval import paired_retrieval
from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.align.train import cosine_warmup_lr, fit_heads


def near_duplicate_pairs(batch: int, dim: int, scale: float, seed: int = 0):
    """l2-normalised float64 pairs whose rows differ by ~1e-3 relative (from norm-`scale` rows)."""
    g = torch.Generator().manual_seed(seed)
    base = torch.randn(1, dim, generator=g, dtype=torch.float64)
    raw_v = scale * (base + 1e-3 * torch.randn(batch, dim, generator=g, dtype=torch.float64))
    raw_t = scale * (base + 1e-3 * torch.randn(batch, dim, generator=g, dtype=torch.float64))
    return l2_normalise(raw_v), l2_normalise(raw_t)


def loss_and_grads(fn, z_v: torch.Tensor, z_t: torch.Tensor, tau: float):
    z_v = z_v.detach().clone().requires_grad_(True)
    z_t = z_t.detach().clone().requires_grad_(True)
    loss = fn(z_v, z_t, tau)
    loss.backward()
    return loss.detach(), z_v.grad, z_t.grad


def assert_grad_close(got: torch.Tensor, ref: torch.Tensor, rtol: float) -> None:
    """Elementwise agreement relative to the gradient's largest entry (float32 vs float64)."""
    assert torch.isfinite(got).all()
    scale = ref.abs().max().item()
    assert (got.double() - ref).abs().max().item() <= rtol * max(scale, 1e-30)


# ---------------------------------------------------------------------------- heads


def test_head_shapes_and_unit_norm():
    heads = AlignHeads(20, 12)
    z_v, z_t = heads(torch.randn(7, 20), torch.randn(7, 12))
    assert z_v.shape == (7, align_heads.OUT_DIM) and z_t.shape == (7, align_heads.OUT_DIM)
    torch.testing.assert_close(z_v.norm(dim=1), torch.ones(7))
    torch.testing.assert_close(z_t.norm(dim=1), torch.ones(7))
    layers = [type(m).__name__ for m in heads.vision.children()]
    assert layers == ["Linear", "LayerNorm", "Linear"]  # GELU is functional between them
    assert heads.vision.fc1.out_features == align_heads.HIDDEN_DIM == 512


def test_l2_normalise_zero_rows_stay_finite_with_finite_gradient():
    x = torch.zeros(3, 5, requires_grad=True)
    y = l2_normalise(x)
    assert torch.equal(y, torch.zeros(3, 5))
    y.sum().backward()
    assert torch.isfinite(x.grad).all()


def test_heads_on_zero_and_constant_features_are_finite():
    heads = AlignHeads(16, 16)
    v = torch.zeros(4, 16)  # LayerNorm sees a constant (bias-only) row
    t = torch.full((4, 16), 3.0)
    z_v, z_t = heads(v, t)
    assert torch.isfinite(z_v).all() and torch.isfinite(z_t).all()
    loss = info_nce(z_v, z_t, 0.07)
    loss.backward()
    assert torch.isfinite(loss)
    assert all(torch.isfinite(p.grad).all() for p in heads.parameters())


# ---------------------------------------------------------------------------- loss


def test_info_nce_equals_reference_symmetric_cross_entropy():
    g = torch.Generator().manual_seed(3)
    z_v = l2_normalise(torch.randn(12, 16, generator=g, dtype=torch.float64))
    z_t = l2_normalise(torch.randn(12, 16, generator=g, dtype=torch.float64))
    got, gv, gt = loss_and_grads(info_nce, z_v.float(), z_t.float(), 0.1)
    ref, rv, rt = loss_and_grads(
        info_nce_reference, z_v.float().double(), z_t.float().double(), 0.1
    )
    assert got.item() == pytest.approx(ref.item(), rel=1e-6)
    assert_grad_close(gv, rv, 1e-5)
    assert_grad_close(gt, rt, 1e-5)
    # and against the closed form with a numpy log-sum-exp, both directions
    s = (z_v.float().double() @ z_t.float().double().T).numpy() / 0.1
    lse_r = np.log(np.exp(s - s.max(1, keepdims=True)).sum(1)) + s.max(1)
    lse_c = np.log(np.exp(s - s.max(0, keepdims=True)).sum(0)) + s.max(0)
    closed = 0.5 * ((lse_r - np.diag(s)).mean() + (lse_c - np.diag(s)).mean())
    assert ref.item() == pytest.approx(closed, rel=1e-12)
    # and torch's own cross_entropy over the float64 similarity matrix, both directions
    logits, target = torch.from_numpy(s), torch.arange(12)
    library = 0.5 * (F.cross_entropy(logits, target) + F.cross_entropy(logits.T, target))
    assert got.item() == pytest.approx(library.item(), rel=1e-6)


def test_info_nce_small_tau_large_norm_near_duplicates_matches_float64():
    z_v, z_t = near_duplicate_pairs(batch=48, dim=128, scale=1e3)
    zv32, zt32 = z_v.float(), z_t.float()
    got, gv, gt = loss_and_grads(info_nce, zv32, zt32, 0.01)
    ref, rv, rt = loss_and_grads(info_nce_reference, zv32.double(), zt32.double(), 0.01)
    assert torch.isfinite(got)
    assert got.item() == pytest.approx(ref.item(), rel=1e-5)
    # Near-duplicate rows make the gradient a difference of nearly equal rows (~1e-3 of its
    # generic size 1/(B tau)), while float32 dot products carry ~1e-7 error that 1/tau = 100
    # amplifies to ~1e-5 in the logits: a relative error ~1e-5/1e-3 = 1e-2 is the float32
    # conditioning of this case, not an implementation error. So: within 1% of the (tiny)
    # gradient, and within 1e-5 of the generic gradient scale 1/(B tau).
    generic = 1.0 / (48 * 0.01)
    for g32, g64 in ((gv, rv), (gt, rt)):
        assert_grad_close(g32, g64, 1e-2)
        assert (g32.double() - g64).abs().max().item() <= 1e-5 * generic
        cos = torch.nn.functional.cosine_similarity(g32.double().flatten(), g64.flatten(), dim=0)
        assert cos.item() > 0.9999


def test_heads_gradients_small_tau_large_norm_inputs_match_float64_heads():
    """End to end: raw features of norm ~1e4, near-duplicate rows, tau = 0.01, through the
    float32 heads and `info_nce`, against a float64 copy of the heads and the reference loss."""
    torch.manual_seed(5)
    heads32 = AlignHeads(24, 24, hidden_dim=64, out_dim=32)
    heads64 = copy.deepcopy(heads32).double()
    g = torch.Generator().manual_seed(9)
    base = torch.randn(1, 24, generator=g, dtype=torch.float64)
    v = 2e3 * (base + 1e-2 * torch.randn(16, 24, generator=g, dtype=torch.float64))
    t = 2e3 * (base + 1e-2 * torch.randn(16, 24, generator=g, dtype=torch.float64))

    loss32 = info_nce(*heads32(v.float(), t.float()), 0.01)
    loss32.backward()
    loss64 = info_nce_reference(*heads64(v, t), 0.01)
    loss64.backward()
    assert torch.isfinite(loss32)
    assert loss32.item() == pytest.approx(loss64.item(), rel=1e-4)
    for (name, p32), p64 in zip(heads32.named_parameters(), heads64.parameters(), strict=True):
        assert torch.isfinite(p32.grad).all(), name
        scale = p64.grad.abs().max().item()
        err = (p32.grad.double() - p64.grad).abs().max().item()
        assert err <= 2e-3 * scale + 1e-9, f"{name}: max err {err:.3g}, grad scale {scale:.3g}"


def test_info_nce_batch_of_one_is_zero_with_zero_gradient():
    z = l2_normalise(torch.randn(1, 8))
    loss, gv, gt = loss_and_grads(info_nce, z, z.flip(1), 0.01)
    assert loss.item() == 0.0
    assert torch.equal(gv, torch.zeros_like(gv)) and torch.equal(gt, torch.zeros_like(gt))
    assert info_nce_reference(z.double(), z.flip(1).double(), 0.01).item() == 0.0


def test_info_nce_all_identical_rows_gives_log_batch():
    row = l2_normalise(torch.randn(1, 32))
    z = row.repeat(10, 1)
    got, gv, _ = loss_and_grads(info_nce, z, z, 0.01)
    ref = info_nce_reference(z.double(), z.double(), 0.01)
    assert got.item() == pytest.approx(math.log(10), rel=1e-6)
    assert ref.item() == pytest.approx(math.log(10), rel=1e-12)
    assert torch.isfinite(gv).all()


def test_info_nce_zero_vectors_are_finite():
    z = l2_normalise(torch.zeros(6, 16))
    got, gv, gt = loss_and_grads(info_nce, z, z, 0.01)
    assert got.item() == pytest.approx(math.log(6), rel=1e-6)
    assert torch.isfinite(gv).all() and torch.isfinite(gt).all()


@settings(max_examples=15, deadline=None)
@given(
    b=st.integers(1, 6),
    d=st.integers(1, 8),
    tau=st.floats(0.01, 2.0),
    seed=st.integers(0, 2**16),
)
def test_info_nce_property_matches_reference(b, d, tau, seed):
    g = torch.Generator().manual_seed(seed)
    z_v = l2_normalise(torch.randn(b, d, generator=g))
    z_t = l2_normalise(torch.randn(b, d, generator=g))
    got = info_nce(z_v, z_t, tau)
    ref = info_nce_reference(z_v.double(), z_t.double(), tau)
    assert got.item() == pytest.approx(ref.item(), rel=1e-5, abs=1e-5)


@pytest.mark.parametrize(
    "shape_v, shape_t, tau",
    [((4, 8), (5, 8), 0.1), ((4, 8), (4, 7), 0.1), ((0, 8), (0, 8), 0.1), ((4, 8), (4, 8), 0.0)],
)
def test_info_nce_rejects_bad_input(shape_v, shape_t, tau):
    with pytest.raises(ValueError, match="info_nce"):
        info_nce(torch.zeros(shape_v), torch.zeros(shape_t), tau)


# ---------------------------------------------------------------------------- schedule


def test_cosine_warmup_schedule():
    total, base = 200, 1e-3
    lrs = [cosine_warmup_lr(s, total, base, 0.05) for s in range(total)]
    assert lrs[0] == pytest.approx(base / 10)  # warm-up of round(0.05 * 200) = 10 steps
    assert lrs[9] == pytest.approx(base)
    assert all(a < b for a, b in zip(lrs[:10], lrs[1:10], strict=False))
    assert all(a >= b for a, b in zip(lrs[10:], lrs[11:], strict=False))
    assert lrs[110] == pytest.approx(base * 0.5 * (1 + math.cos(math.pi * 100 / 190)))
    assert 0 < lrs[-1] < 1e-3 * base


# ---------------------------------------------------------------------------- training


def synthetic_pairs(n: int, dv: int, dt: int, noise: float, seed: int):
    """T = V A + noise: touch is a noisy linear map of vision (so alignment is learnable)."""
    rng = np.random.default_rng(seed)
    v = rng.standard_normal((n, dv)).astype(np.float32)
    a = rng.standard_normal((dv, dt)) / np.sqrt(dv)
    t = (v @ a + noise * rng.standard_normal((n, dt))).astype(np.float32)
    return v, t


def saved_bytes(result) -> bytes:
    buf = io.BytesIO()
    torch.save(align_checkpoint.heads_payload(result), buf)
    return buf.getvalue()


def test_fit_heads_is_bit_reproducible_and_seeded(tmp_path):
    v, t = synthetic_pairs(300, 16, 12, noise=0.5, seed=1)
    tr, va = np.arange(240), np.arange(240, 300)
    kw = dict(tau=0.07, settings=AlignSettings.tiny(steps=30, eval_every=10), device="cpu")
    before = torch.get_rng_state()
    r1 = fit_heads(v, t, tr, va, seed=11, **kw)
    assert torch.equal(before, torch.get_rng_state())  # global RNG untouched
    r2 = fit_heads(v, t, tr, va, seed=11, **kw)
    r3 = fit_heads(v, t, tr, va, seed=12, **kw)
    save_heads(r1, tmp_path / "a.pt")
    save_heads(r2, tmp_path / "b.pt")
    assert (tmp_path / "a.pt").read_bytes() == (tmp_path / "b.pt").read_bytes()
    for part in ("vision", "tactile"):
        for k, val in r1.heads[part].items():
            assert val.numpy().tobytes() == r2.heads[part][k].numpy().tobytes()
    assert r1.curve == r2.curve
    assert saved_bytes(r1) != saved_bytes(r3)


def test_fit_heads_reaches_clearly_above_chance_on_noisy_linear_pairs():
    """T is a noisy linear map of V. Margin: under chance the number of correct top-1 among
    n_val queries is ~Binomial(n_val, 1/n_val); we require the observed count to have a
    chance tail probability < 1e-9, and top-1 at least half that of a closed-form
    least-squares linear map V -> T fitted on the same training pairs (a trainer that works
    must recover a comparable share of a purely linear relation)."""
    v, t = synthetic_pairs(800, 32, 24, noise=1.0, seed=0)
    tr, va = np.arange(600), np.arange(600, 800)
    res = fit_heads(
        v,
        t,
        tr,
        va,
        tau=0.07,
        seed=0,
        settings=AlignSettings.tiny(budget="epochs", epochs=30, eval_every=100, batch_size=128),
        device="cpu",
    )
    assert res.total_steps == 30 * (600 // 128) == res.steps_run
    z_v, z_t = project(res, v[va], t[va], device="cpu")
    m = paired_retrieval(z_v, z_t)
    n = m["n"]
    hits = round(m["top1_v2t"] * n)
    assert binom.sf(hits - 1, n, 1 / n) < 1e-9, m
    w, *_ = np.linalg.lstsq(v[tr], t[tr], rcond=None)
    linear = paired_retrieval(v[va] @ w, t[va])
    assert m["top1_v2t"] >= 0.5 * linear["top1_v2t"], (m, linear)
    assert m["top1_t2v"] >= 0.5 * linear["top1_t2v"], (m, linear)
    assert res.curve[-1]["val_loss"] < res.curve[0]["val_loss"] - 1.0


def test_early_stopping_keeps_best_weights():
    """20% of the validation pairs are scrambled: the val loss first falls (the relation is
    learned) and then rises (growing confidence is punished on the scrambled pairs). Training
    must stop `patience` evaluations after the best one, and the returned weights must be those
    of the best evaluation, not the last."""
    v, t = synthetic_pairs(400, 16, 16, noise=0.3, seed=2)
    tr, va = np.arange(300), np.arange(300, 400)
    t = t.copy()
    scrambled = va[:20]
    t[scrambled] = t[np.random.default_rng(0).permutation(scrambled)]
    patience, every = 3, 5
    res = fit_heads(
        v,
        t,
        tr,
        va,
        tau=0.07,
        seed=0,
        settings=AlignSettings.tiny(steps=400, patience=patience, eval_every=every, batch_size=100),
        device="cpu",
    )
    assert res.stopped_early and res.steps_run < res.total_steps == 400
    losses = [c["val_loss"] for c in res.curve]
    best = int(np.argmin(losses))
    assert res.best_step == res.curve[best]["step"] > 0  # a U-shaped curve, not the init
    assert res.steps_run == res.best_step + patience * every
    assert len(res.curve) == best + patience + 1
    # the kept weights reproduce the best validation loss (one chunk: n_val == batch_size)
    z_v, z_t = project(res, v[va], t[va], device="cpu")
    kept = info_nce(torch.from_numpy(z_v), torch.from_numpy(z_t), 0.07).item()
    assert kept == pytest.approx(res.best_val_loss, rel=1e-5)
    assert abs(kept - losses[-1]) > 1e-3


def test_progress_gets_one_line_per_evaluation():
    v, t = synthetic_pairs(120, 8, 8, noise=0.5, seed=3)
    lines: list[str] = []
    settings = AlignSettings.tiny(steps=12, eval_every=5)
    split = np.arange(100), np.arange(100, 120)
    res = fit_heads(
        v, t, *split, tau=0.1, seed=0, settings=settings, progress=lines.append, device="cpu"
    )
    assert [c["step"] for c in res.curve] == [0, 5, 10, 12]
    assert len(lines) == 4 and "val_loss" in lines[-1] and "step 12/12" in lines[-1]


def test_save_load_project_round_trip(tmp_path):
    v, t = synthetic_pairs(150, 10, 6, noise=0.5, seed=4)
    settings = AlignSettings.tiny(steps=8, eval_every=4)
    res = fit_heads(
        v, t, np.arange(120), np.arange(120, 150), tau=0.1, seed=3, settings=settings, device="cpu"
    )
    path = tmp_path / "sub" / "heads.pt"
    save_heads(res, path)
    loaded = load_heads(path)
    assert loaded.meta["best_step"] == res.best_step and loaded.meta["curve"] == res.curve
    state, back = res.module().state_dict(), loaded.state_dict()
    assert state.keys() == back.keys()
    for k, w in state.items():  # the file gives back every weight bit for bit
        assert torch.equal(back[k], w), k
    a_v, a_t = project(res, v, t, device="cpu")
    b_v, b_t = project(loaded, v, t, device="cpu")
    assert a_v.dtype == np.float32 and a_v.shape == (150, 128) and a_t.shape == (150, 128)
    # the loaded heads are another computation (their kernels may be others): within rounding
    # of a head (Linear, LayerNorm, Linear, l2 norm: five chained sums of <= HIDDEN_DIM terms)
    for a, b in ((a_v, b_v), (a_t, b_t)):
        atol = reordered_sum_atol(a, terms=align_heads.HIDDEN_DIM, depth=5)
        np.testing.assert_allclose(b, a, rtol=0, atol=atol)
    np.testing.assert_allclose(np.linalg.norm(a_v, axis=1), 1.0, rtol=1e-5)
    (tmp_path / "junk.pt").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="junk.pt"):
        load_heads(tmp_path / "junk.pt")


def test_fit_heads_refuses_overlap_and_misaligned_rows():
    v, t = synthetic_pairs(50, 4, 4, noise=0.5, seed=5)
    kw = dict(tau=0.1, seed=0, settings=AlignSettings.tiny(steps=2, eval_every=1), device="cpu")
    with pytest.raises(ValueError, match="both train_idx and val_idx"):
        fit_heads(v, t, np.arange(30), np.arange(25, 50), **kw)
    with pytest.raises(ValueError, match="rows"):
        fit_heads(v, t[:40], np.arange(30), np.arange(30, 40), **kw)
    with pytest.raises(ValueError, match="budget"):
        AlignSettings.tiny(budget="minutes")
    bad = v.copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError, match="row 7"):
        fit_heads(bad, t, np.arange(30), np.arange(30, 50), **kw)
