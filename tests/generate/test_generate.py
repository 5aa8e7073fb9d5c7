"""The latent generator: schedules, denoiser, samplers, training and evaluation.

Hard cases against float64 references written as plain loops here: schedule
endpoints, the clipped posterior log-variance at t = 0, fp32 posterior coefficients at every
t, DDIM with one step, guidance 0 and 10, a batch of one, identical conditions, a tactile
dimension with zero variance, and sampling identical given the same seed.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import torch
import yaml
from generate_worlds import evaluate_one, small_probes, toy_specs, toy_world, train_ids
from rounding import reordered_sum_atol
from scipy import linalg
from snakemake.utils import update_config
from snakemake_run import ROOT

from tacgen_lib.generate.baselines import (
    BASELINE_INPUTS,
    TargetSpec,
    baselines_frame,
    baselines_from_frame,
    fit_baselines,
)
from tacgen_lib.generate.evaluate import evaluate_generator, shuffled_rows
from tacgen_lib.generate.fidelity import (
    cosine_pairing,
    fidelity,
    frechet_distance,
    pairing_permutation,
)
from tacgen_lib.generate.inference import DenoiserArrays, read_generator
from tacgen_lib.generate.model import Denoiser, fit_standardiser, sinusoidal_embedding
from tacgen_lib.generate.sampling import (
    ddim_timesteps,
    generate,
    guided_output,
    guided_output_projected,
    predicted_x0_eps,
    project_guidance,
    sample,
)
from tacgen_lib.generate.sampling_cells import guidance_text, sample_cells
from tacgen_lib.generate.schedules import cosine_betas, linear_betas, make_schedule
from tacgen_lib.generate.settings import GenerateSettings, check_grid
from tacgen_lib.generate.train import (
    fit_generator,
    load_generator,
    make_optimiser,
    save_generator,
    training_step,
)
from tacgen_lib.probes.fit import fit_probe
from tacgen_lib.probes.logistic import FixedLogistic
from tacgen_lib.probes.rows import family_rows
from tacgen_lib.report.findings import generation_findings
from tacgen_lib.workflow_config import validate_config

SCHEMA = ROOT / "config" / "config.schema.yaml"


# ------------------------------------------------------------------ float64 references


def schedule_reference(betas: list[float]) -> dict[str, list[float]]:
    """alpha-bar and the posterior coefficients by plain float64 loops (DDPM eq. 6-7)."""
    abar, prod = [], 1.0
    for b in betas:
        prod *= 1.0 - b
        abar.append(prod)
    out = {"abar": abar, "var": [], "coef1": [], "coef2": []}
    for t, b in enumerate(betas):
        prev = abar[t - 1] if t > 0 else 1.0
        out["var"].append(b * (1.0 - prev) / (1.0 - abar[t]))
        out["coef1"].append(b * math.sqrt(prev) / (1.0 - abar[t]))
        out["coef2"].append((1.0 - prev) * math.sqrt(1.0 - b) / (1.0 - abar[t]))
    return out


def random_denoiser(dim_t=6, dim_v=5, hidden=16, blocks=2, seed=0) -> Denoiser:
    """A denoiser with a non-zero output layer (the zero init would make eps = 0)."""
    torch.manual_seed(seed)
    model = Denoiser(dim_t, dim_v, hidden, blocks, time_dim=8)
    with torch.no_grad():
        model.out.weight.normal_(0, 0.3)
        model.out.bias.normal_(0, 0.1)
        model.null_condition.normal_(0, 1)
    return model.eval()


def ddim_reference(model, schedule, cond, x_T, steps, guidance, prediction):
    """DDIM (eta = 0) in float64: the model run in double, loops over steps."""
    m = Denoiser(**model.dims).double()
    m.load_state_dict({k: v.double() for k, v in model.state_dict().items()})
    m.eval()
    abar = schedule.alphas_cumprod
    ts = ddim_timesteps(schedule.n_steps, steps)
    x = torch.from_numpy(x_T).double()
    c = torch.from_numpy(cond).double()
    with torch.no_grad():
        for i, t in enumerate(ts):
            tt = torch.full((x.shape[0],), int(t))
            out_c = m(x, tt, c)
            out_u = m(x, tt, c, torch.ones(x.shape[0], dtype=torch.bool))
            o = out_u + guidance * (out_c - out_u)
            a, s = math.sqrt(abar[t]), math.sqrt(1.0 - abar[t])
            if prediction == "eps":
                x0, eps = (x - s * o) / a, o
            else:
                x0, eps = a * x - s * o, s * x + a * o
            prev = abar[ts[i + 1]] if i + 1 < len(ts) else 1.0
            x = math.sqrt(prev) * x0 + math.sqrt(1.0 - prev) * eps
    return x.numpy()


def initial_noise(n, d, seed):
    """The first draw of `sample`'s noise generator (numpy PCG64, float32)."""
    return np.random.default_rng(seed).standard_normal((n, d), dtype=np.float32)


def normal32(*shape, seed=0):
    return np.random.default_rng(seed).standard_normal(shape, dtype=np.float32)


#: How far one float32 denoiser pass output (of size ~1) may move when the same rows are
#: computed in another batch shape, where BLAS may pick another kernel (OpenBLAS's
#: Haswell kernels against SkylakeX moved them by 2.4e-7): eps 1.2e-7 x sqrt(16) for the
#: reordered sums of hidden = 16 terms, x sqrt(8) over the chained products (inp, 2 x (emb,
#: fc1, fc2), out) ~ 1.4e-6. A guided output u + w (c - u) weighs two passes' drifts by
#: |1 - w| + |w|.
PASS_DRIFT = 2e-6


def guided_drift(guidance: float) -> float:
    """`PASS_DRIFT` of a guided output at `guidance`: (|1 - w| + |w|) PASS_DRIFT."""
    return (abs(1.0 - guidance) + abs(guidance)) * PASS_DRIFT


# ------------------------------------------------------------------ schedules


@pytest.mark.parametrize("name", ["cosine", "linear"])
def test_schedule_endpoints_are_finite_and_match_float64_loops(name):
    sch = make_schedule(name, 1000)
    ref = schedule_reference(list(sch.betas))
    assert np.all(sch.betas <= 0.999) and np.all(sch.betas > 0)
    assert 0.0 < sch.alphas_cumprod[-1] < 1e-3  # alpha-bar_T near 0 but not 0
    assert np.isfinite(1.0 / np.sqrt(sch.alphas_cumprod[-1]))
    np.testing.assert_allclose(sch.alphas_cumprod, ref["abar"], rtol=1e-12)
    np.testing.assert_allclose(sch.posterior_variance, ref["var"], rtol=1e-9, atol=1e-300)
    np.testing.assert_allclose(sch.posterior_mean_coef1, ref["coef1"], rtol=1e-9)
    np.testing.assert_allclose(sch.posterior_mean_coef2, ref["coef2"], rtol=1e-9, atol=1e-300)


def test_cosine_first_alpha_bar_rounds_to_one_in_float32_yet_coefficients_stay_finite():
    """alpha-bar_0 = 1 - 4e-5 in float64; in float32 1 - alpha-bar_0 loses most digits. The
    coefficients are formed in float64 first, so the float32 copies are finite and exact."""
    sch = make_schedule("cosine", 1000)
    assert np.float32(sch.alphas_cumprod[0]) > 0.9999
    naive = np.float32(1.0) - np.float32(sch.alphas_cumprod[0])
    assert abs(naive - (1.0 - sch.alphas_cumprod[0])) / (1.0 - sch.alphas_cumprod[0]) > 1e-4
    for name, values in sch.arrays(np.float32).items():
        assert values.dtype == np.float32 and np.isfinite(values).all(), name
        ref = getattr(sch, name)
        np.testing.assert_allclose(
            values.astype(np.float64), ref, rtol=1e-6, atol=1e-30, err_msg=name
        )


def test_clipped_posterior_log_variance_at_t0():
    for name in ("cosine", "linear"):
        sch = make_schedule(name, 1000)
        assert sch.posterior_variance[0] == 0.0  # the true posterior variance at t = 0
        assert np.isfinite(sch.posterior_log_variance).all()
        assert sch.posterior_log_variance[0] == pytest.approx(np.log(sch.posterior_variance[1]))
        np.testing.assert_allclose(
            sch.posterior_log_variance[1:], np.log(sch.posterior_variance[1:]), rtol=1e-12
        )


def test_unclipped_cosine_would_end_at_alpha_bar_zero():
    """Why the clip exists: without it the last beta is 1 and alpha-bar_T is exactly 0."""
    assert cosine_betas(1000, max_beta=1.0)[-1] == pytest.approx(1.0)
    assert cosine_betas(1000)[-1] == 0.999
    assert linear_betas(1000)[0] == pytest.approx(1e-4) and linear_betas(1000)[-1] == 0.02


def test_sinusoidal_embedding_matches_float64_formula():
    t = torch.tensor([0, 1, 500, 999])
    got = sinusoidal_embedding(t, 9).double().numpy()
    freqs = np.exp(-np.log(10_000.0) * np.arange(4) / 4)
    args = np.array([0, 1, 500, 999], dtype=np.float64)[:, None] * freqs
    ref = np.hstack([np.cos(args), np.sin(args), np.zeros((4, 1))])
    np.testing.assert_allclose(got, ref, atol=2e-4)


# ------------------------------------------------------------------ samplers


@pytest.mark.parametrize("prediction", ["eps", "v"])
@pytest.mark.parametrize("steps", [1, 5])
def test_ddim_matches_float64_reference(prediction, steps):
    sch = make_schedule("cosine", 1000)
    model = random_denoiser()
    cond = np.random.default_rng(1).normal(size=(7, 5)).astype(np.float32)
    got = sample(
        model.arrays(),
        sch,
        cond,
        sampler="ddim",
        steps=steps,
        guidance=1.5,
        seed=3,
        prediction=prediction,
        eta=0.0,
        batch=2048,
    )
    ref = ddim_reference(model, sch, cond, initial_noise(7, 6, 3), steps, 1.5, prediction)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, ref, rtol=1e-3, atol=1e-3 * np.abs(ref).max())


def test_numpy_forward_equals_the_torch_module():
    """Sampling runs the denoiser in numpy (`DenoiserArrays`, no torch import); it must be the
    torch module's forward up to float32 rounding, conditional and null-condition rows, and
    close to the module run in float64."""
    model = random_denoiser(hidden=32, blocks=3)
    arrays = model.arrays()
    x, c = normal32(11, 6, seed=1), normal32(11, 5, seed=2)
    t = np.array([999, 998, 700, 500, 250, 100, 10, 3, 2, 1, 0])
    drop = np.arange(11) % 3 == 0
    with torch.no_grad():
        ref = model(
            torch.from_numpy(x), torch.from_numpy(t), torch.from_numpy(c), torch.from_numpy(drop)
        ).numpy()
        m64 = Denoiser(**model.dims).double()
        m64.load_state_dict({k: v.double() for k, v in model.state_dict().items()})
        ref64 = m64(
            torch.from_numpy(x).double(),
            torch.from_numpy(t),
            torch.from_numpy(c).double(),
            torch.from_numpy(drop),
        ).numpy()
    got = arrays.forward(x, t, c, drop)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(got, ref64, rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="lacks"):
        DenoiserArrays.from_state({"inp.weight": np.zeros((2, 2))}, model.dims)


def test_sampling_modules_do_not_import_torch_or_pandas():
    """What a sample_generator job imports: the weights reader, the samplers, the edges, the
    cells' seed and timing files and the forked workers (its start-up: torch ~1.2 s, pandas
    ~0.25 s)."""
    code = (
        "import sys; import tacgen_lib.generate.inference, tacgen_lib.generate.sampling, "
        "tacgen_lib.generate.sampling_cells, tacgen_lib.runtime.benchmarks, tacgen_lib.runtime.workers, "
        "tacgen_lib.io.edges, tacgen_lib.io.log, tacgen_lib.runtime.device, threadpoolctl; "
        "print('torch' in sys.modules, 'pandas' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False False"


@pytest.mark.parametrize("guidance", [0.0, 10.0])
def test_guidance_extremes_stay_finite_and_w0_is_unconditional(guidance):
    model = random_denoiser().arrays()
    x = normal32(4, 6, seed=1)
    t = np.array([999, 500, 1, 0])
    c = normal32(4, 5, seed=2)
    out = guided_output(model, x, t, c, guidance)
    assert np.isfinite(out).all()
    u = model.forward(x, t, c, np.ones(4, dtype=bool))
    cnd = model.forward(x, t, c)
    # `out` comes from one pass over 2B = 8 rows, u and cnd from passes over B = 4 rows:
    # another batch shape, within rounding (`guided_drift`: 3.8e-5 at w = 10)
    np.testing.assert_allclose(
        out, u + guidance * (cnd - u), rtol=1e-6, atol=guided_drift(guidance)
    )
    if guidance == 0.0:
        # w = 0 is the unconditional half of that same 8-row pass bit for bit (u + 0 (c - u)
        # is u): the same computation, so exact; against the 4-row `u` it is the check above
        drop = np.repeat([False, True], 4)
        half = model.forward(
            np.concatenate([x, x]), np.concatenate([t, t]), np.concatenate([c, c]), drop
        )[4:]
        np.testing.assert_array_equal(out, half)
    sch = make_schedule("cosine", 1000)
    z = sample(
        model,
        sch,
        c,
        sampler="ddim",
        steps=10,
        guidance=guidance,
        seed=0,
        prediction="v",
        eta=0.0,
        batch=2048,
    )
    assert np.isfinite(z).all()


def test_batch_of_one_and_identical_conditions():
    model = random_denoiser().arrays()
    sch = make_schedule("linear", 100)
    kw = dict(sampler="ddpm", steps=100, guidance=2.0, seed=0, prediction="v", eta=0.0, batch=2048)
    one = sample(model, sch, np.ones((1, 5), np.float32), **kw)
    assert one.shape == (1, 6) and np.isfinite(one).all()
    same = sample(model, sch, np.ones((32, 5), np.float32), **kw)
    assert np.isfinite(same).all()
    assert np.unique(same.round(6), axis=0).shape[0] == 32  # the noise still varies rows
    # one-row guidance equals the batched computation row by row
    x, t, c = normal32(3, 6, seed=1), np.array([10, 20, 30]), normal32(3, 5, seed=2)
    batched = guided_output(model, x, t, c, 3.0)
    rows = np.concatenate(
        [guided_output(model, x[i : i + 1], t[i : i + 1], c[i : i + 1], 3.0) for i in range(3)]
    )
    # one row per pass against three: another batch shape, within rounding (`guided_drift`:
    # 1e-5 at w = 3; 3e-7 seen with OpenBLAS's Haswell kernels)
    np.testing.assert_allclose(batched, rows, rtol=1e-5, atol=guided_drift(3.0))


@pytest.mark.parametrize("guidance", [0.0, 1.0, 3.0])
def test_projected_condition_matches_the_plain_forward(guidance):
    """`sample`'s shortcut (condition share of the embeddings once per batch, time MLP on one
    row) equals the plain CFG forward up to float32 rounding, and against float64."""
    module = random_denoiser()
    model = module.arrays()
    x, c = normal32(9, 6, seed=1), normal32(9, 5, seed=2)
    m64 = Denoiser(**module.dims).double()
    m64.load_state_dict({k: v.double() for k, v in module.state_dict().items()})
    projected = project_guidance(model, c, guidance)
    assert projected[0].shape[0] == 9 * (1 if guidance in (0.0, 1.0) else 2)  # passes w needs
    for t in (999, 500, 1, 0):
        plain = guided_output(model, x, np.full(9, t), c, guidance)
        got = guided_output_projected(model, x, t, projected, guidance)
        # the fast path splits each embedding product (W time + b) + W cond and runs other
        # batch shapes: within rounding (`guided_drift` <= 1e-5 for w <= 3; 1.2e-6 seen)
        np.testing.assert_allclose(got, plain, rtol=1e-5, atol=1e-5)
        if guidance in (0.0, 1.0):
            # the one pass at w = 0 / 1 is exactly the unconditional / conditional projected
            # forward of these 9 rows: the same computation, so bit for bit
            drop = np.full(9, guidance == 0.0)
            alone = model.forward_projected(x, t, model.project_condition(c, drop))
            np.testing.assert_array_equal(got, alone)
            # and the matching half of a two-pass batch of 18 rows up to rounding: another
            # batch shape (`PASS_DRIFT`)
            both = model.project_condition(np.concatenate([c, c]), np.concatenate([~drop, drop]))
            one = model.forward_projected(np.concatenate([x, x]), t, both)[9:]
            np.testing.assert_allclose(got, one, rtol=1e-6, atol=PASS_DRIFT)
        with torch.no_grad():
            xx, cc, tt = (
                torch.from_numpy(x).double(),
                torch.from_numpy(c).double(),
                torch.full((9,), t),
            )
            u = m64(xx, tt, cc, torch.ones(9, dtype=torch.bool))
            ref = (u + guidance * (m64(xx, tt, cc) - u)).numpy()
        np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-5)


def test_training_step_is_bit_reproducible_with_the_fused_optimiser():
    s = GenerateSettings.tiny(prediction="v")
    sch = make_schedule("cosine", 100)
    sa = torch.from_numpy(np.sqrt(sch.alphas_cumprod)).float()
    s1 = torch.from_numpy(np.sqrt(sch.one_minus_alphas_cumprod)).float()

    def run():
        torch.manual_seed(0)
        model = Denoiser(6, 5, s.hidden, s.blocks, s.time_dim)
        ema = Denoiser(6, 5, s.hidden, s.blocks, s.time_dim)
        ema.load_state_dict(model.state_dict())
        opt = make_optimiser(list(model.parameters()), s)
        gen = torch.Generator().manual_seed(1)
        for _ in range(5):
            batch = (
                torch.randn(8, 6, generator=gen),
                torch.randn(8, 5, generator=gen),
                torch.randint(0, 100, (8,), generator=gen),
                torch.randn(8, 6, generator=gen),
                torch.rand(8, generator=gen) < 0.1,
            )
            loss = training_step(model, opt, list(ema.parameters()), batch, sa, s1, s)
        return loss.item(), [p.detach().clone() for p in ema.parameters()]

    (l1, p1), (l2, p2) = run(), run()
    assert l1 == l2 and np.isfinite(l1)
    for a, b in zip(p1, p2, strict=True):
        assert torch.equal(a, b)


def test_ddpm_final_step_is_the_posterior_mean_and_x0_inverts():
    sch = make_schedule("cosine", 1000)
    tens = sch.arrays()
    x0 = normal32(5, 3, seed=1)
    eps = normal32(5, 3, seed=2)
    for t in (0, 1, 500, 999):
        a = np.float32(math.sqrt(sch.alphas_cumprod[t]))
        s = np.float32(math.sqrt(1 - sch.alphas_cumprod[t]))
        x_t = a * x0 + s * eps
        v = a * eps - s * x0
        got_x0, got_eps = predicted_x0_eps(v, x_t, a, s, "v")
        np.testing.assert_allclose(got_x0, x0, rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(got_eps, eps, rtol=1e-4, atol=1e-4)
    assert float(tens["posterior_log_variance"][0]) == pytest.approx(
        float(np.log(sch.posterior_variance[1])), rel=1e-6
    )


def test_sampling_is_identical_given_the_same_seed():
    model = random_denoiser().arrays()
    sch = make_schedule("cosine", 1000)
    cond = np.random.default_rng(0).normal(size=(9, 5)).astype(np.float32)
    kw = {"sampler": "ddim", "steps": 7, "guidance": 2.0, "prediction": "v", "eta": 0.5}
    kw["batch"] = 2048
    a = sample(model, sch, cond, seed=11, **kw)
    b = sample(model, sch, cond, seed=11, **kw)
    c = sample(model, sch, cond, seed=12, **kw)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_ddim_timesteps_and_sampler_checks():
    assert list(ddim_timesteps(1000, 1)) == [999]
    ts = ddim_timesteps(1000, 50)
    assert ts[0] == 999 and ts[-1] == 0 and np.all(np.diff(ts) < 0) and len(ts) == 50
    assert len(ddim_timesteps(10, 10)) == 10
    with pytest.raises(ValueError, match="DDIM steps"):
        ddim_timesteps(10, 11)
    with pytest.raises(ValueError, match="all T = 100"):
        sample(
            random_denoiser().arrays(),
            make_schedule("linear", 100),
            np.ones((1, 5), np.float32),
            sampler="ddpm",
            steps=10,
            guidance=1.0,
            seed=0,
            eta=0.0,
            batch=2048,
            prediction="eps",
        )
    with pytest.raises(ValueError, match="generate.samplers.ddpm"):
        check_grid({"ddpm": [50]}, 1000)
    with pytest.raises(ValueError, match="unknown sampler"):
        check_grid({"plms": [5]}, 1000)
    check_grid({"ddim": [1, 1000], "ddpm": [1000]}, 1000)


# ------------------------------------------------------------------ standardisation + training


def test_zero_variance_dimension_is_centred_not_divided_by_zero():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(50, 4))
    x[:, 2] = 3.25  # constant in the train split
    std = fit_standardiser(x)
    assert std.scale[2] == 1.0
    z = std.forward(x)
    assert np.isfinite(z).all() and np.all(z[:, 2] == 0.0)
    np.testing.assert_allclose(std.inverse(z), x, rtol=1e-12, atol=1e-12)


def linear_pairs(n=160, dv=5, dt=4, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, dv)).astype(np.float32)
    w = rng.normal(size=(dv, dt))
    t = (v @ w + 0.1 * rng.normal(size=(n, dt))).astype(np.float32)
    return v, t


def test_training_with_a_constant_dimension_is_finite_and_bit_reproducible(tmp_path):
    v, t = linear_pairs()
    t[:, 1] = 7.0
    s = GenerateSettings.tiny()
    a = fit_generator(t[:120], v[:120], t[120:], v[120:], s, seed=4, device="cpu")
    b = fit_generator(t[:120], v[:120], t[120:], v[120:], s, seed=4, device="cpu")
    for k, val in a.model.state_dict().items():
        assert torch.equal(val, b.model.state_dict()[k]), k
    assert all(np.isfinite(c["val_loss"]) for c in a.curve)
    gen = generate(
        a.weights(), v[120:], sampler="ddim", steps=5, guidance=1.0, seed=0, eta=0.0, batch=2048
    )
    assert np.isfinite(gen).all()
    h1 = save_generator(a, tmp_path / "a.arrow")
    h2 = save_generator(b, tmp_path / "b.arrow")
    assert h1 == h2  # same fit, same bytes
    back = load_generator(tmp_path / "a.arrow")  # torch model, for training-side use
    for k, val in a.model.state_dict().items():
        assert torch.equal(val, back.model.state_dict()[k]), k
    read = read_generator(tmp_path / "a.arrow")  # what sample_generator reads, without torch
    assert read.curve == a.curve and read.best_step == a.best_step and read.settings == s
    np.testing.assert_array_equal(read.standardiser.scale, a.standardiser.scale)
    np.testing.assert_array_equal(read.standardiser.mean, a.standardiser.mean)
    arrays = a.weights().denoiser.params
    assert read.denoiser.params.keys() == arrays.keys()
    for k, w in arrays.items():  # the file gives back every array bit for bit
        np.testing.assert_array_equal(read.denoiser.params[k], w, err_msg=k)
    # sampling with the read arrays is another computation than with the fit's (a reloaded
    # model): within rounding of its 5 DDIM steps, each one denoiser pass (the input layer,
    # per block its norm, embedding and two layers, the head's norm and output layer)
    again = generate(
        read, v[120:], sampler="ddim", steps=5, guidance=1.0, seed=0, eta=0.0, batch=2048
    )
    atol = reordered_sum_atol(gen, terms=s.hidden, depth=5 * (3 + 4 * s.blocks))
    np.testing.assert_allclose(again, gen, rtol=0, atol=atol)
    (tmp_path / "a.arrow").write_bytes((tmp_path / "a.arrow").read_bytes() + b"x")
    with pytest.raises(ValueError, match="does not match"):
        load_generator(tmp_path / "a.arrow")
    (tmp_path / "c.arrow").write_bytes(b"not arrow")
    with pytest.raises(ValueError, match="c.arrow: not a readable generator"):
        read_generator(tmp_path / "c.arrow", verify=False)


def test_v_prediction_generator_learns_a_linear_map():
    """On T = V W + small noise, generated T must correlate with the truth far above chance."""
    v, t = linear_pairs(n=400)
    s = GenerateSettings.tiny(
        steps=600, hidden=64, blocks=2, lr=2e-3, prediction="v", train_steps=1000, time_dim=32
    )
    fit = fit_generator(t[:300], v[:300], t[300:350], v[300:350], s, seed=0, device="cpu")
    gen = generate(
        fit.weights(), v[350:], sampler="ddim", steps=20, guidance=1.0, seed=0, eta=0.0, batch=2048
    )
    r = np.corrcoef(gen.ravel(), t[350:].ravel())[0, 1]
    assert r > 0.8, r


# ------------------------------------------------------------------ evaluation


def frechet_reference(a, b):
    """The textbook form with scipy.linalg.sqrtm (complex round-off dropped)."""
    mu = a.mean(0) - b.mean(0)
    sa, sb = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    cross = linalg.sqrtm(sa @ sb).real
    return float(mu @ mu + np.trace(sa + sb - 2 * cross))


def test_frechet_distance_matches_scipy_and_is_zero_on_itself():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(200, 5)), rng.normal(1.0, 2.0, size=(150, 5))
    assert frechet_distance(a, b) == pytest.approx(frechet_reference(a, b), rel=1e-6)
    assert frechet_distance(a, a) == pytest.approx(0.0, abs=1e-8)
    low_rank = np.repeat(rng.normal(size=(100, 1)), 4, axis=1)  # singular covariance
    assert np.isfinite(frechet_distance(low_rank, a[:100, :4]))


def test_cosine_pairing_and_permutation_check():
    rng = np.random.default_rng(0)
    real = rng.normal(size=(60, 8))
    gen = real + 0.3 * rng.normal(size=(60, 8))
    matched, off = cosine_pairing(gen, real)
    assert matched > 0.9 and abs(off) < 0.1
    obs, null, p = pairing_permutation(gen, real, 200, seed=0)
    assert obs == matched and null.shape == (200,) and p == pytest.approx(1 / 201)
    _, _, p_null = pairing_permutation(rng.normal(size=(60, 8)), real, 200, seed=0)
    assert p_null > 0.01
    fid, draws = fidelity(gen[:30], real[:30], real[30:], n_permutations=50, seed=0)
    assert draws.shape == (50,) and fid["frechet"] >= 0 and fid["frechet_real_ref"] >= 0


@pytest.mark.parametrize("n", [2, 3, 10, 101])
def test_shuffled_rows_break_every_pairing(n):
    perm = shuffled_rows(n, seed=1)
    assert sorted(perm) == list(range(n)) and not np.any(perm == np.arange(n))


def test_evaluation_real_touch_helps_where_generated_touch_cannot():
    """The label depends on an attribute only touch sees: V+T_real gains, V+T_gen (a function
    of V) does not, and the summary has every input with its CI."""
    ids, v, t, manifest, splits = toy_world()
    train = splits["split"] == "train"
    s = GenerateSettings.tiny(
        steps=300,
        hidden=64,
        blocks=2,
        lr=2e-3,
        prediction="v",
        train_steps=200,
        time_dim=32,
        permutations=100,
    )
    val = (splits["split"] == "val").to_numpy()
    fit = fit_generator(
        t[train.to_numpy()], v[train.to_numpy()], t[val], v[val], s, seed=0, device="cpu"
    )
    gen = generate(
        fit.weights(), v, sampler="ddim", steps=10, guidance=1.0, seed=0, eta=0.0, batch=2048
    )
    rows = family_rows(manifest, splits, corpus="toy", target="force_p50", kind="ridge")
    ps = small_probes("ridge", [0.1, 1, 10], [1], bootstrap=500)
    spec = TargetSpec("force_p50", rows, ps)
    vision, t_real = dict(zip(ids, v, strict=True)), dict(zip(ids, t, strict=True))
    t_gen = {("ddim", "1", "10"): dict(zip(ids, gen, strict=True))}
    generator_train_ids = train_ids(splits)
    summary, perms = evaluate_one(
        spec,
        vision,
        t_real,
        t_gen,
        seed=0,
        permutations=100,
        generator_train_ids=generator_train_ids,
    )
    by = summary.set_index("input")
    assert set(by.index) == {
        "t_real",
        "t_gen",
        "t_gen_shuffled",
        "v_nonlinear",
        "t_ridge",
        "t_ridge_residual",
    }
    assert summary["row_id"].is_unique and len(perms) == 100
    assert by.loc["t_real", "ci_low"] > 0.3  # touch sees the hidden attribute
    assert by.loc["t_gen", "ci_low"] <= 0.0 < by.loc["t_real", "delta"]
    assert by.loc["t_gen", "cos_matched"] > by.loc["t_gen", "cos_offdiag"]
    for col in ("score", "delta", "ci_low", "ci_high"):
        assert np.isfinite(by[col]).all()


def test_baselines_edge_round_trip_is_exact_and_checked():
    """The baselines edge gives back the fitted predictions bit for bit (floats) and as the
    training labels (logistic); rows of other splits or unknown labels are refused by name."""
    ids, vision, t_real, specs = toy_specs()
    fits = [fit_baselines(s, vision, t_real, gammas=(0.5, 2.0)) for s in specs]
    frame = baselines_frame("toy", specs, fits)
    assert frame["row_id"].is_unique
    assert len(frame) == sum(3 * s.rows.n_test for s in specs)
    back = baselines_from_frame(frame, specs)
    for spec, fit in zip(specs, fits, strict=True):
        got = back[spec.name]
        assert got.reg == fit.reg and got.gamma == fit.gamma
        for inp in BASELINE_INPUTS:
            np.testing.assert_array_equal(got.pred[inp], fit.pred[inp])
            if spec.settings.kind == "logistic":
                assert set(got.pred[inp]) <= set(spec.rows.y_train)
    # the fits are the probes stage's own: V alone equals fit_probe on V
    v_tr = np.stack([vision[i] for i in specs[0].rows.train_ids])
    v_te = np.stack([vision[i] for i in specs[0].rows.test_ids])
    own = fit_probe(v_tr, specs[0].rows.y_train, v_te, specs[0].settings)
    np.testing.assert_array_equal(fits[0].pred["v"], own.pred_test)
    # a row missing (an edge built on other splits) and a label no class has
    missing = frame.drop(index=frame.index[(frame["target"] == "hardness")][0])
    with pytest.raises(
        ValueError, match=r"baselines\.parquet: target 'hardness' input 'v'.*1 missing"
    ):
        baselines_from_frame(missing, specs, source="baselines.parquet")
    odd = frame.copy()
    odd.loc[odd.index[odd["target"] == "hardness"][0], "label"] = "medium"
    with pytest.raises(ValueError, match="'medium' is not a training class"):
        baselines_from_frame(odd, specs)


def test_evaluation_of_two_seeds_shares_the_baselines():
    """V, V+T_real and the nonlinear V rows do not depend on the generator seed: both seeds'
    rows equal, and the baselines read from the edge give the same summary as the fits."""
    ids, vision, t_real, specs = toy_specs()
    fits = {s.name: fit_baselines(s, vision, t_real, gammas=(1.0,)) for s in specs}
    edge = baselines_from_frame(baselines_frame("toy", specs, list(fits.values())), specs)
    rng = np.random.default_rng(5)
    cell = ("ddim", "1", "5")

    def run(seed, baselines):
        gen = {i: x + rng.normal(size=x.shape) for i, x in vision.items()}
        return evaluate_generator(
            specs,
            corpus="toy",
            seed=seed,
            vision=vision,
            t_real=t_real,
            t_gen={cell: gen},
            baselines=baselines,
            permutations=10,
            generator_train_ids=train_ids(toy_world()[4]),
        )[0]

    s0, s1 = run(0, fits), run(1, edge)
    shared = [
        "target",
        "input",
        "score",
        "v_score",
        "delta",
        "ci_low",
        "ci_high",
        "reg",
        "nonlinear_gamma",
        "delta_vs_nonlinear",
    ]
    for inp in ("t_real", "v_nonlinear"):
        a = s0.loc[s0["input"] == inp, shared].reset_index(drop=True)
        b = s1.loc[s1["input"] == inp, shared].reset_index(drop=True)
        pd.testing.assert_frame_equal(a, b)
    with pytest.raises(ValueError, match="no baselines for target 'hardness'"):
        run(0, {"force_p50": fits["force_p50"]})


def test_logistic_c_is_chosen_on_the_reference_cell_and_reused():
    """The logistic C of V+T_gen and of the shuffled control comes from the reference cell's
    CV; every other cell refits at that C. The reference cell's rows equal per-cell CV, and a
    reused-C fit equals the probe's own final fit at that C."""
    ids, v, t, manifest, splits = toy_world()
    rng = np.random.default_rng(3)
    manifest["hardness"] = np.where(manifest["force_p50"] > 0, "hard", "soft")
    rows = family_rows(manifest, splits, corpus="toy", target="hardness", kind="logistic")
    ps = small_probes("logistic", [1], [0.01, 1, 100])
    cells = {
        ("ddim", str(w), "5"): dict(zip(ids, v @ rng.normal(size=(4, 4)) + w * t, strict=True))
        for w in (0, 1, 3)
    }
    spec = TargetSpec("hardness", rows, ps)
    vision, t_real = dict(zip(ids, v, strict=True)), dict(zip(ids, t, strict=True))
    kw = dict(seed=0, permutations=10, generator_train_ids=train_ids(splits))
    summary, _ = evaluate_one(spec, vision, t_real, cells, **kw, reference=("ddim", "1", "5"))
    gen = summary[summary["input"].isin(["t_gen", "t_gen_shuffled"])].set_index(
        ["input", "guidance"]
    )
    assert (gen.xs(1.0, level="guidance")["reg_source"] == "cv").all()
    assert (gen.drop(index=1.0, level="guidance")["reg_source"] == "reference cell").all()
    for inp in ("t_gen", "t_gen_shuffled"):
        assert gen.loc[inp, "reg"].nunique() == 1  # one C per input kind
    assert (summary.loc[summary["input"] == "t_real", "reg_source"] == "cv").all()

    def block(src, sel):
        return np.stack([src[i] for i in sel]).astype(np.float64)

    vis = dict(zip(ids, v, strict=True))
    for w in ("1", "3"):  # the CV cell, and a reused-C cell
        g = cells[("ddim", w, "5")]
        x_tr = np.hstack([block(vis, rows.train_ids), block(g, rows.train_ids)])
        x_te = np.hstack([block(vis, rows.test_ids), block(g, rows.test_ids)])
        own = fit_probe(x_tr, rows.y_train, x_te, ps)
        c_ref = float(gen.loc[("t_gen", 1.0), "reg"])
        refit = FixedLogistic(c_ref).fit_predict(x_tr, rows.y_train, x_te)
        score = float(gen.loc[("t_gen", float(w)), "score"])
        assert score == pytest.approx(float(np.mean(refit == rows.y_test)), abs=1e-12)
        if w == "1" or float(own.reg) == c_ref:  # same C: the refit is the probe's final fit
            np.testing.assert_array_equal(refit, own.pred_test)


# ------------------------------------------------------------------ settings + cells


def validated(overlay=None):
    cfg = yaml.safe_load((ROOT / "config/config.yaml").read_text())
    if overlay:
        update_config(cfg, yaml.safe_load((ROOT / "config" / overlay).read_text()))
    cfg["scenes_file"] = str(ROOT / cfg["scenes_file"])
    return validate_config(cfg, SCHEMA)


@pytest.mark.parametrize("overlay", [None, "test.yaml", "paper.yaml"])
def test_every_config_builds_generate_settings_and_a_valid_grid(overlay):
    cfg = validated(overlay)["generate"]
    s = GenerateSettings.from_config(cfg)
    assert s.hidden == cfg["hidden"] and s.steps == cfg["steps"]
    check_grid(cfg["samplers"], cfg["train_steps"])
    assert len(sample_cells(cfg["guidance"], cfg["samplers"])) >= 1


def test_every_generate_settings_field_is_a_config_key():
    schema = yaml.safe_load(SCHEMA.read_text())["properties"]["generate"]["properties"]
    assert {f.name for f in dataclasses.fields(GenerateSettings)} <= set(schema)


def test_generate_settings_refuse_bad_values_naming_the_key():
    with pytest.raises(ValueError, match="generate.prediction"):
        GenerateSettings.tiny(prediction="x0")
    with pytest.raises(ValueError, match="generate.p_uncond"):
        GenerateSettings.tiny(p_uncond=1.5)
    # the one settings reader: a missing key keeps the field's default (the schema's, which
    # fills it at start-up), an unknown one is refused naming it
    section = validated()["generate"]
    missing = GenerateSettings.from_config({k: v for k, v in section.items() if k != "hidden"})
    assert missing.hidden == GenerateSettings().hidden
    with pytest.raises(ValueError, match="generate.hiden: unknown key"):
        GenerateSettings.from_config({**section, "hiden": 64})
    assert GenerateSettings.tiny().steps <= 100 and GenerateSettings.tiny(steps=5).steps == 5


def test_guidance_text_is_canonical():
    assert guidance_text(1.0) == "1" and guidance_text("1.50") == "1.5" and guidance_text(0) == "0"
    with pytest.raises(ValueError):
        guidance_text(-1)


# ------------------------------------------------------------------ report


def synthetic_summary() -> pd.DataFrame:
    rows = []
    for corpus, design, null, target in (
        ("sim_paired", "paired", False, "force_p50"),
        ("sim_controlled", "controlled", False, "density"),
        ("sim_null", "paired", True, "force_p50"),
    ):
        for seed in (0, 1):
            for w in (0.0, 1.0):
                for inp, d in (
                    ("t_real", 0.3),
                    ("t_gen", 0.05 * seed),
                    ("t_gen_shuffled", 0.0),
                    ("v_nonlinear", 0.02),
                    ("t_ridge", 0.04),
                    ("t_ridge_residual", 0.01),
                ):
                    rows.append(
                        {
                            "row_id": f"{corpus}|{target}|{seed}|{w}|{inp}",
                            "corpus": corpus,
                            "target": target,
                            "metric": "accuracy" if design == "controlled" else "r2",
                            # the controlled rows' V (0.5) is below their majority rate
                            "baseline_score": 0.6 if design == "controlled" else 0.0,
                            "seed": seed,
                            "sampler": "ddim",
                            "guidance": w,
                            "steps": 10,
                            "input": inp,
                            "score": 0.5 + d,
                            "v_score": 0.5,
                            "delta": d,
                            "ci_low": d - 0.1,
                            "ci_high": d + 0.1,
                            "delta_vs_nonlinear": d - 0.02,
                            "ci_low_vs_nonlinear": d - 0.12,
                            "ci_high_vs_nonlinear": d + 0.08,
                            "delta_vs_ridge": d - 0.04 if inp == "t_gen" else np.nan,
                            "ci_low_vs_ridge": d - 0.3 if inp == "t_gen" else np.nan,
                            "ci_high_vs_ridge": d - 0.01 if inp == "t_gen" else np.nan,
                            "design": design,
                            "null_corpus": null,
                            "cos_matched": 0.6 if inp == "t_ridge" else 0.3,
                            "cos_offdiag": 0.1,
                            "pairing_p": 0.01,
                            "frechet": 2.0,
                            "frechet_real_ref": 1.0,
                        }
                    )
    return pd.DataFrame(rows)


def test_heatmap_text_colour_follows_cell_luminance():
    from tacgen_lib.report.generate import text_colour

    assert text_colour((0.0, 0.0, 0.3, 1.0)) == "white"  # dark blue
    assert text_colour((0.4, 0.0, 0.05, 1.0)) == "white"  # dark red
    assert text_colour((0.97, 0.97, 0.97, 1.0)) == "black"  # the colour map's middle
    assert text_colour((1.0, 0.8, 0.7)) == "black"


def test_protocol_table_averages_guidance_per_seed_then_seeds():
    from tacgen_lib.report import generate as rep

    rows = synthetic_summary()
    ref = {"sampler": "ddim", "steps": 10, "guidance": "1"}
    # a third guidance value (w = 3) and a third seed: seed s, w -> 0.1 s + 0.01 w; w = 0 is
    # unconditional and left out
    extra = []
    for seed in (0, 1, 2):
        for w in (1.0, 3.0):
            r = rows[(rows["corpus"] == "sim_paired") & (rows["seed"] == min(seed, 1))]
            r = r[r["guidance"] == 1.0].copy()
            r["seed"], r["guidance"] = seed, w
            r.loc[r["input"] == "t_gen", "delta"] = 0.1 * seed + 0.01 * w
            r["row_id"] = r["row_id"] + f"|{seed}|{w}"
            extra.append(r)
    rows = pd.concat([rows[rows["corpus"] != "sim_paired"], *extra], ignore_index=True)
    rows.loc[rows["guidance"] == 0.0, "delta"] = 99.0  # w = 0 must not count
    table = rep.protocol_table(rows, ref).set_index("corpus")
    paired = table.loc["sim_paired"]
    per_seed = np.array([0.02, 0.12, 0.22])  # mean over w in {1, 3} of 0.1 s + 0.01 w
    m, lo, hi = rep.cross_seed_interval(per_seed)
    assert paired["Δ_gen cross-seed [95% t]"] == f"{m:+.3f} [{lo:+.3f}, {hi:+.3f}]"
    assert paired["seeds × guidance"] == "3 × 2 (1, 3)"
    assert paired["Δ_real"] == "+0.300"
    assert paired["real inside the interval"] == ("yes" if lo <= 0.3 <= hi else "no")
    assert paired["Δ_gen > 0 (interval above 0)"] == ("yes" if lo > 0 else "no")


def test_report_tables_and_figures_from_a_summary():
    import matplotlib

    matplotlib.use("Agg")
    from tacgen_lib.report import generate as rep

    rows = synthetic_summary()
    seconds = {("sim_paired", 0, "ddim", 1.0, 10): 2.5}
    summary = rep.generation_summary(rows, seconds, {("sim_paired", 0): 9.0})
    assert summary["sample_seconds"].notna().sum() == 6  # one cell: its 6 inputs
    ref = {"sampler": "ddim", "steps": 10, "guidance": "1"}
    head = rep.headline_table(summary, ref)
    assert len(head) == 3 and "Δ_real (protocol-matched)" in head.columns
    paired = head.set_index("corpus").loc["sim_paired"]
    assert paired["Δ_gen seed 0 [bootstrap CI]"] == "+0.000 [-0.100, +0.100]"
    assert paired["Δ ridge V→T"] == "+0.040 [-0.060, +0.140]"
    assert paired["Δ_gen − ridge V→T"] == "-0.040 [-0.300, -0.010]"
    # a V probe below the constant prediction is flagged beside its score
    flags = head.set_index("corpus")["V below majority"]
    assert flags["sim_controlled"] == "yes: Δ is no evidence" and flags["sim_paired"] == "no"
    mean, lo, hi = rep.cross_seed_interval(np.array([0.0, 0.05]))
    assert mean == pytest.approx(0.025) and lo < 0 < hi
    part = generation_findings(summary, ref)
    found = part.rows.set_index("question")
    by_id = {d["decision_id"]: d["decision"] for d in part.decisions}
    assert by_id["generation|sim_controlled|density|v_vs_majority"] == "below majority"
    # Δ_gen − ridge: seed 0's interval [-0.30, -0.01] lies below 0, seed 1's [-0.25, +0.04]
    # does not; the generator seeds are read as one, so no seed's draw decides alone
    assert by_id["generation|sim_controlled|density|vs_ridge"] == "no measurable difference"
    controlled = found.loc[found.index.str.contains("sim_controlled"), "verdict"].iloc[0]
    assert "⚠ V accuracy 0.500 below the majority-class rate 0.600" in controlled
    assert "2 generator seeds read as one" in found.loc[found.index[0], "result"]
    seed0 = generation_findings(summary[summary["seed"] == 0], ref)
    assert {d["decision_id"]: d["decision"] for d in seed0.decisions}[
        "generation|sim_controlled|density|vs_ridge"
    ] == "below 0"
    controlled = seed0.rows.set_index("question")
    controlled = controlled.loc[controlled.index.str.contains("sim_controlled"), "verdict"].iloc[0]
    assert "V + T_gen scores below V + ridge V→T" in controlled  # Δ_gen − ridge CI < 0
    paired = found.loc[found.index.str.contains("sim_paired"), "verdict"].iloc[0]
    assert "⚠" not in paired and "not measurably paired" not in paired
    honesty = rep.honesty_table(summary, ref)
    verdict = honesty.set_index(["corpus", "seed", "input"])["as expected"]
    assert verdict[("sim_controlled", 0, "t_real")] == "yes"  # CI (0.2, 0.4) > 0
    assert verdict[("sim_controlled", 0, "t_gen")] == "yes"  # CI covers 0
    assert verdict[("sim_null", 0, "t_real")] == "NO"  # real touch "helps" on the null corpus
    fid = rep.fidelity_table(summary)
    # 3 corpora x 2 seeds: 2 diffusion cells each, then the ridge generator's 2 arms
    assert len(fid) == 24
    first = fid[(fid["corpus"] == "sim_paired") & (fid["seed"] == 0)]
    assert list(first["generator"]) == [
        "diffusion",
        "diffusion",
        "ridge V→T (mean)",
        "ridge V→T + residual",
    ]
    assert list(first["cos matched"]) == ["0.300", "0.300", "0.600", "0.300"]
    assert list(first["guidance"][2:]) == ["—", "—"] and list(first["sample s"][2:]) == ["—", "—"]
    perms = pd.DataFrame(
        {
            "corpus": "sim_paired",
            "seed": 0,
            "target": "force_p50",
            "sampler": "ddim",
            "guidance": 1.0,
            "steps": 10,
            "statistic": np.linspace(-0.1, 0.1, 50),
            "observed": 0.3,
        }
    )
    curves = pd.DataFrame(
        {
            "corpus": "sim_paired",
            "seed": 0,
            "step": [10, 20],
            "train_loss": [1.0, 0.5],
            "val_loss": [1.1, 0.6],
        }
    )
    rng = np.random.default_rng(0)
    for fig in (
        rep.guidance_seed_figure(summary, "ddim", 10),
        rep.steps_seconds_figure(summary),
        rep.permutation_figure(perms, ref),
        rep.curve_figure(curves),
        rep.pca_figure(rng.normal(size=(30, 5)), rng.normal(size=(30, 5)), title="x"),
    ):
        assert len(fig.axes) >= 1


def test_cell_seed_is_the_per_cell_jobs_seed_and_cells_keep_their_paths():
    """One job per generator samples each cell with the seed a job per cell used (generator
    seed, steps, guidance in thousandths), so the edges stay the same bytes; its outputs are
    the cells' paths with corpus and seed left as wildcards, in the cells' order."""
    from tacgen_lib.generate.sampling_cells import (
        SAMPLE_CELL,
        cell_seed,
        generator_cells,
        sample_cells,
    )

    assert cell_seed(0, "1", "25") == 25 * 101 + 1000
    assert cell_seed("3", 1.5, 1000) == 3 * 1_000_003 + 1000 * 101 + 1500
    assert cell_seed(1, "0", "5") != cell_seed(1, "0", "10")
    cells = sample_cells([0, 1.5], {"ddim": [5], "ddpm": [1000]})
    paths = generator_cells(SAMPLE_CELL, cells)
    assert paths[0] == "results/generate/{corpus}/seed~{seed}/sampler~ddim/guidance~0/steps~5"
    assert paths[-1].endswith("sampler~ddpm/guidance~1.5/steps~1000") and len(paths) == 4
