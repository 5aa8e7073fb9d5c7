"""The config key `device` (tacgen_lib.runtime.device): how each value resolves here, that the
schema offers exactly those values, and, where a CUDA GPU can be used, config/test.yaml's torch
rules run on it and the GPU's numbers agree with the CPU's within float tolerance. Where no GPU
can be used the GPU tests skip, saying why (`cuda_unavailable`). The CPU path's bit identity is
the workflow tests' business (every edge of config/test.yaml, which runs with device: cpu)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import yaml
from snakemake_run import ROOT, copy_tree, smk

from tacgen_lib.runtime.device import DEVICES, cuda_unavailable, torch_device

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


def test_the_schema_offers_exactly_these_values_and_defaults_to_cpu():
    schema = yaml.safe_load((ROOT / "config" / "config.schema.yaml").read_text())
    key = schema["properties"]["device"]
    assert tuple(key["enum"]) == DEVICES and key["default"] == "cpu"


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
        extract_features(model, images, **kw),
        rtol=1e-3,
        atol=1e-3,
    )
    v, t = rng.normal(size=(64, 16)), rng.normal(size=(64, 12))
    settings = AlignSettings.tiny()
    tr, va = np.arange(48), np.arange(48, 64)
    a = fit_heads(v, t, tr, va, tau=0.1, seed=1, settings=settings, device=gpu)
    b = fit_heads(v, t, tr, va, tau=0.1, seed=1, settings=settings)
    assert a.best_val_loss == pytest.approx(b.best_val_loss, rel=1e-3, abs=1e-4)
    vv = rng.normal(size=(120, 5))
    tt = vv @ rng.normal(size=(5, 4))
    fit = fit_generator(tt[:100], vv[:100], tt[100:], vv[100:], GenerateSettings.tiny(), seed=2)
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
def test_config_test_torch_rules_run_on_the_gpu(tmp_path):
    """config/test.yaml with device: cuda, every rule (the torch ones on the GPU): the run
    succeeds and its generated vectors are finite."""
    from tacgen_lib.io import edges

    work = copy_tree(tmp_path / "gpu")
    smk(work, "--config", "device=cuda", timeout=1800)
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
