"""The config key `device` (tacgen_lib.runtime.device): how each value resolves here, the device
spec a rule passes (with `allow_tf32`), the TF32 setting, that the schema offers exactly those
values, and, where a CUDA GPU can be used, config/test.yaml's torch rules run on it and the
GPU's numbers agree with the CPU's within the stated tolerances. Where no GPU can be used the
GPU tests skip, saying why (`cuda_unavailable`). The CPU path's bit identity is the workflow
tests' business (every edge of config/test.yaml, which runs with device: cpu)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import yaml
from snakemake_run import ROOT, copy_tree, smk

from tacgen_lib.runtime.device import (
    DEVICES,
    configure_cuda_math,
    cuda_unavailable,
    device_spec,
    parse_device_spec,
    torch_device,
)

NO_GPU = cuda_unavailable()
needs_gpu = pytest.mark.skipif(NO_GPU is not None, reason=f"no CUDA GPU: {NO_GPU}")


def test_cpu_is_the_cpu_and_an_unknown_name_is_refused():
    assert torch_device("cpu") == torch.device("cpu")
    with pytest.raises(ValueError, match="'gpu'.*cpu, cuda, auto"):
        torch_device("gpu")


def test_auto_takes_a_gpu_only_where_there_is_one():
    assert torch_device("auto").type == ("cpu" if NO_GPU else "cuda")


@pytest.mark.skipif(NO_GPU is None, reason="a CUDA GPU is usable here")
def test_cuda_without_a_gpu_stops_saying_why():
    with pytest.raises(RuntimeError, match="config device: cuda, but"):
        torch_device("cuda")


def test_the_schema_offers_exactly_these_values_and_defaults_to_cpu_without_tf32():
    schema = yaml.safe_load((ROOT / "config" / "config.schema.yaml").read_text())
    key = schema["properties"]["device"]
    assert tuple(key["enum"]) == DEVICES and key["default"] == "cpu"
    tf32 = schema["properties"]["allow_tf32"]
    assert tf32["type"] == "boolean" and tf32["default"] is False


def test_the_device_spec_carries_tf32_only_where_a_gpu_may_compute():
    """A rule's params: the config's device, +tf32 where allow_tf32 and the device can be a
    GPU; cpu stays cpu (its params, and so a CPU run's jobs, never change with the key)."""
    assert device_spec("cpu", False) == device_spec("cpu", True) == "cpu"
    assert (device_spec("cuda", False), device_spec("cuda", True)) == ("cuda", "cuda+tf32")
    assert device_spec("auto", True) == "auto+tf32"
    for spec, parsed in [("cpu", ("cpu", False)), ("cuda+tf32", ("cuda", True))]:
        assert parse_device_spec(spec) == parsed
    for bad in ("gpu", "cuda+fp16", "cpu+"):
        with pytest.raises(ValueError, match="expected one of cpu, cuda, auto"):
            parse_device_spec(bad)
    with pytest.raises(ValueError, match="'gpu'"):
        device_spec("gpu", False)
    assert torch_device("auto+tf32").type == ("cpu" if NO_GPU else "cuda")


@pytest.fixture
def cuda_math_flags():
    """torch's process-wide GPU arithmetic flags, put back after the test."""
    b = torch.backends
    saved = (
        b.cudnn.benchmark,
        b.cudnn.deterministic,
        b.cuda.matmul.allow_tf32,
        b.cudnn.allow_tf32,
    )
    yield
    (
        b.cudnn.benchmark,
        b.cudnn.deterministic,
        b.cuda.matmul.allow_tf32,
        b.cudnn.allow_tf32,
    ) = saved


def test_tf32_is_off_unless_allowed(cuda_math_flags):
    """cuBLAS matrix products and cuDNN convolutions in float32 by default (torch's own default
    lets cuDNN's convolutions use TF32); allow_tf32 turns both on. The flags are settable on a
    CPU build, so this runs everywhere; torch's matmul precision reads back without the error
    it raises for a mix of its two TF32 interfaces."""
    b = torch.backends
    configure_cuda_math(False)
    assert (b.cuda.matmul.allow_tf32, b.cudnn.allow_tf32) == (False, False)
    assert (b.cudnn.benchmark, b.cudnn.deterministic) == (False, True)
    assert torch.get_float32_matmul_precision() == "highest"
    configure_cuda_math(True)
    assert (b.cuda.matmul.allow_tf32, b.cudnn.allow_tf32) == (True, True)


@needs_gpu
def test_gpu_numbers_agree_with_the_cpus_within_tolerance():
    """The same features, heads and sampler on the GPU and the CPU: within float tolerance
    (not bit for bit: other kernels, other reduction orders)."""
    from tacgen_lib.align.settings import AlignSettings
    from tacgen_lib.align.train import fit_heads
    from tacgen_lib.features.extract import extract_features
    from tacgen_lib.features.vit import random_backbone
    from tacgen_lib.generate.sampling import generate
    from tacgen_lib.generate.sampling_torch import generate_torch
    from tacgen_lib.generate.settings import GenerateSettings
    from tacgen_lib.generate.train import fit_generator

    gpu = torch_device("cuda")
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, size=(8, 56, 56, 3), dtype=np.uint8)
    model = random_backbone("vit_tiny", 56, seed=0)
    kw = dict(image_size=56, batch_size=4, pool="cls")
    np.testing.assert_allclose(
        extract_features(model, images, device=gpu, **kw),
        extract_features(model, images, device="cpu", **kw),
        rtol=1e-3,
        atol=1e-3,
    )
    v, t = rng.normal(size=(64, 16)), rng.normal(size=(64, 12))
    settings = AlignSettings.tiny()
    tr, va = np.arange(48), np.arange(48, 64)
    a = fit_heads(v, t, tr, va, tau=0.1, seed=1, settings=settings, device=gpu)
    b = fit_heads(v, t, tr, va, tau=0.1, seed=1, settings=settings, device="cpu")
    assert a.best_val_loss == pytest.approx(b.best_val_loss, rel=1e-3, abs=1e-4)
    vv = rng.normal(size=(120, 5))
    tt = vv @ rng.normal(size=(5, 4))
    fit = fit_generator(
        tt[:100], vv[:100], tt[100:], vv[100:], GenerateSettings.tiny(), seed=2, device="cpu"
    )
    cond = vv[:20]
    cell = dict(sampler="ddim", steps=10, guidance=1.5, seed=3, eta=0.0, batch=8)
    np.testing.assert_allclose(
        generate_torch(fit.weights(), cond, device=gpu, **cell),
        generate(fit.weights(), cond, **cell),
        rtol=1e-3,
        atol=1e-3,
    )
    gpu_fit = fit_generator(
        tt[:100], vv[:100], tt[100:], vv[100:], GenerateSettings.tiny(), seed=2, device=gpu
    )
    again = fit_generator(
        tt[:100], vv[:100], tt[100:], vv[100:], GenerateSettings.tiny(), seed=2, device=gpu
    )
    # same GPU, same seed: within tolerance (the promise), and on the CPU when it comes back
    for name, arr in gpu_fit.weights().denoiser.params.items():
        np.testing.assert_allclose(arr, again.weights().denoiser.params[name], rtol=1e-4, atol=1e-5)


@needs_gpu
@pytest.mark.workflow
@pytest.mark.timeout(3000)  # the CPU reference run (if this session has not made it) and this one
def test_config_test_on_the_gpu_agrees_with_the_cpu_run_stage_by_stage(reference_run, tmp_path):
    """config/test.yaml with device: cuda, every rule (the torch ones on the GPU, each holding
    the `gpu` resource): every stage's vector edges within its tolerance of the session's CPU
    run (tacgen_lib.io.run_compare.STAGE_TOLERANCES, docs/cluster.md), the findings' decisions
    the same where the run states them, and the generated vectors finite."""
    from tacgen_lib.io import edges
    from tacgen_lib.io.run_compare import compare_decisions, stage_differences

    work = copy_tree(tmp_path / "gpu")
    smk(work, "--config", "device=cuda", timeout=2400)
    stages = stage_differences(reference_run, work)
    assert {s.stage for s in stages} >= {"features", "align", "generate", "pixel", "policy"}
    report = "\n".join(
        f"{s.stage}: {s.max_rel:.3g} (tolerance {s.tolerance:g}) at {s.worst.edge} "
        f"[{s.worst.column}] {s.worst.worst_key!r} {s.worst.note}"
        for s in stages
    )
    print(report)
    assert all(s.within for s in stages), report
    decisions = compare_decisions(reference_run, work)
    assert decisions is None or decisions.agree, decisions
    outs = sorted((work / "results" / "generate").rglob("t_gen.parquet"))
    assert outs, "no generated vectors"
    for path in outs:
        ids, vec = edges.read_vectors(path, "t_gen")
        assert len(ids) and np.isfinite(vec).all(), path


def _rule_blocks() -> list[tuple[str, str, str]]:
    """(rule file, rule name, the rule's text) of every rule in rules/*.smk."""
    import re

    out = []
    for smk_file in sorted((ROOT / "rules").glob("*.smk")):
        for block in re.split(r"(?m)^(?=\s*rule \w+:)", smk_file.read_text()):
            m = re.search(r"rule (\w+):", block)
            if m:
                out.append((smk_file.name, m.group(1), block))
    return out


def test_every_rule_whose_script_picks_a_device_passes_the_configs():
    """A script that calls `torch_device(snakemake.params.device)` needs `device=DEVICE` in
    the params of every rule that runs it (a rule without it fails at run time); and the
    parameter makes a change of device rerun the job."""
    import re

    pickers = {
        p.name
        for p in (ROOT / "workflow" / "scripts").glob("*.py")
        if re.search(r"params\.device\b", p.read_text())
    }
    assert len(pickers) >= 10, pickers
    seen = set()
    for smk_file, rule, block in _rule_blocks():
        script = re.search(r"scripts/(\w+\.py)", block)
        if script and script.group(1) in pickers:
            seen.add(script.group(1))
            assert "device=DEVICE" in block, f"{smk_file}: rule {rule} lacks device=DEVICE"
    assert seen == pickers
