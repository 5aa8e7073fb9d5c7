"""The work units of each rule's jobs: the one table the run-time estimate is built on.

A job's predicted wall time is `overhead + cost_per_unit × units + FLOPs / rate`
(tacgen_lib.runtime.calibration fits the first two per cost class on benchmark files; the FLOP term,
for rules with a model, is charged at the CPU's effective GEMM rate so that a model 100x
larger than any calibrated one costs 100x its arithmetic, not 100x its calibrated overheads). `UNITS` has one line per rule: what one unit is,
and how many a job has, read from the merged config and the job's wildcards. A rule may split
its jobs into cost classes (a probe family's solver kind and protocol variant cost differently
per row); a class is `rule` or `rule:<what>`.

The counts are proportional to the work the job's code does (rows × steps × model size), not
exact: early stopping (align `patience`, generator `patience`) can end training before its
budget, so those rules' predictions are upper-side. Changing a rule's code or its config keys
may change its units: edit its line here, then regenerate the shipped calibration
(`python -m tacgen_lib.runtime.calibration`, README "Run-time estimate").
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from tacgen_lib.features.archs import ARCHS, RESNET_ARCHS, arch_family
from tacgen_lib.generate.cells import guidance_passes
from tacgen_lib.generate.regime_sets import regime_corpora
from tacgen_lib.io.config import load_yaml

__all__ = [
    "UnitRule",
    "UNITS",
    "GFLOPS_PER_THREAD",
    "job_units",
    "flop_seconds",
    "MissingUnitsError",
]

Config = Mapping[str, Any]
Wildcards = Mapping[str, str]


class MissingUnitsError(KeyError):
    """A rule of the DAG has no line in `UNITS` (or a config it cannot count)."""

    def __str__(self) -> str:  # KeyError quotes its message; this one reads as a sentence
        return str(self.args[0])


@dataclass(frozen=True)
class UnitRule:
    """How one rule's jobs are counted: `unit` says what one unit is (for the printed table),
    `count(config, wildcards) -> (class suffix, units)`; an empty suffix is the rule itself.
    `flops(config, wildcards)`, for rules whose time grows with a model's size, is the job's
    dense floating-point work (multiply-add = 2): it is charged at the CPU's effective GEMM
    rate (`GFLOPS_PER_THREAD`), so a bigger model costs more without a fitted term for it.
    `same_as`: another rule whose calibration prices these jobs (the same kind of work, where
    this rule never runs in a calibration run).
    `cells(config, wildcards) -> [(units, FLOPs), ...]`, for a job that runs independent cells
    in one-thread workers, one per thread (`tacgen_lib.runtime.workers.fork_map`): the job's
    units and FLOPs are the cells' sums, and its wall is the overhead plus the longest-first
    schedule of its cells on its threads (`tacgen_lib.runtime.estimate.job_prediction`)."""

    unit: str
    count: Callable[[Config, Wildcards], tuple[str, float]]
    flops: Callable[[Config, Wildcards], float] | None = None
    same_as: str | None = None
    cells: Callable[[Config, Wildcards], list[tuple[float, float]]] | None = None
    #: whether its FLOPs run in torch, so on a GPU class (`estimate --gpu-tflops`) at the
    #: GPU's rate; False for numpy arithmetic (the latent generator's sampler)
    on_gpu: bool = True


#: Effective dense float32 rate per thread of the calibration's CPU (2-core AMD EPYC, AVX-512):
#: half its measured GEMM peak of 100 GFLOP/s per thread (README, Speed: training reaches
#: 0.58-0.69 of the roofline at batch 256, less on small layers). Scale with --speed-factor on
#: another CPU class.
GFLOPS_PER_THREAD = 50.0


# ---- helpers: sizes read from the merged config --------------------------------------------


def _corpus(c: Config, name: str) -> Mapping[str, Any]:
    return c["corpora"][name]


@functools.cache
def _scene_effects(scenes_file: str) -> dict[str, tuple[str, ...]]:
    """Scene name -> its declared effects, read once from the scenes file ({} if absent)."""
    try:
        scenes = load_yaml(scenes_file) or {}
    except FileNotFoundError:
        return {}
    return {name: tuple(decl.get("effects", ())) for name, decl in scenes.items()}


def _presses(c: Config, name: str) -> float:
    """Presses a simulated sample costs: its jittered presses (`presses`, default 8) where its
    scene declares press_jitter, else the one nominal press."""
    corpus = _corpus(c, name)
    effects = _scene_effects(str(c.get("scenes_file", "config/scenes.yaml"))).get(
        str(corpus.get("scene")), ("press_jitter",)
    )
    return float(corpus.get("presses", 8)) if "press_jitter" in effects else 1.0


def _natural_grid_units(c: Config) -> float:
    """A shard of the regime's rho grid (rule simulate_natural_grid): its samples × (presses ×
    tactile pixels, once for the grid + one render per corpus of the grid)."""
    grid = regime_corpora(c.get("regime"))
    first = next(iter(grid))
    c = {**c, "corpora": {**(c.get("corpora") or {}), **grid}}  # the DAG joins them too
    per_sample = _presses(c, first) * _tactile_pixels(c, first) + len(grid)
    return _n(c, first) / int(_corpus(c, first)["shards"]) * per_sample


def _n(c: Config, name: str) -> float:
    """Samples of a corpus: `n` of a simulated one; a real one's size is not in config (1)."""
    return float(_corpus(c, name).get("n", 1))


def _tactile_pixels(c: Config, name: str) -> float:
    """Tactile pixels of a simulated corpus's frames relative to 120 × 160 (1 for a real one)."""
    h, w = _corpus(c, name).get("tactile_size", (120, 160))
    return float(h) * float(w) / (120.0 * 160.0)


def _train_rows(c: Config, name: str) -> float:
    return _n(c, name) * float(c["splits"]["fractions"]["train"])


def _vit_flops(arch: str, image_size: int) -> float:
    """FLOPs of one frame through a ViT forward: 2 × depth × tokens × (12 width² + 2 tokens ×
    width) (projections and MLP, attention)."""
    width, depth = ARCHS[arch].embed_dim, ARCHS[arch].depth
    tokens = (int(image_size) // ARCHS[arch].patch_size) ** 2 + 1
    return 2.0 * depth * tokens * (12 * width**2 + 2 * tokens * width)


def _resnet_flops(arch: str, image_size: int) -> float:
    """FLOPs of one frame through a ResNet forward: 2 × output pixels × k² × C_in × C_out per
    convolution (the 7×7 stem at 1/2, two 3×3 per block at each stage's resolution from 1/4
    to 1/32, the first block's stride and 1×1 projection included)."""
    cfg = RESNET_ARCHS[arch]
    side = int(image_size) / 2.0
    flops = 2.0 * side * side * 49 * 3 * cfg.widths[0]
    side /= 2.0  # max-pool
    c_in = cfg.widths[0]
    for stage, (blocks, width) in enumerate(zip(cfg.blocks, cfg.widths, strict=True)):
        if stage:
            side /= 2.0
        for b in range(blocks):
            flops += 2.0 * side * side * 9 * (c_in * width + width * width)
            if b == 0 and c_in != width:
                flops += 2.0 * side * side * c_in * width
            c_in = width
    return flops


def _arch_flops(arch: str, image_size: int) -> float:
    """Forward FLOPs of one frame through a named backbone of either family."""
    if arch_family(arch) == "resnet":
        return _resnet_flops(arch, image_size)
    return _vit_flops(arch, image_size)


def _backbone(c: Config, modality: str) -> float:
    """`_arch_flops` of a modality's backbone at the config's input size."""
    return _arch_flops(c["features"]["backbones"][modality]["arch"], c["features"]["image_size"])


#: MAE pretraining per frame and epoch, in encoder forwards: the encoder sees a quarter of the
#: patches, forward + backward (3 forwards), plus the light decoder (about one more)
_MAE_FORWARDS = 1.75


def _pretraining(c: Config, spec: Mapping[str, Any]) -> tuple[str, int]:
    """(how a backbone is made, its pretraining epochs): "checkpoint" and "random" train
    nothing; "dino" runs features.pretrain.epochs, "mae" features.mae.epochs."""
    if spec.get("checkpoint"):
        return "checkpoint", 0
    objective = spec.get("objective", "dino")
    if objective == "mae":
        return objective, int(c["features"].get("mae", {}).get("epochs", 10))
    if objective == "dino":
        return objective, int(c["features"]["pretrain"]["epochs"])
    return objective, 0


def _pretraining_units(c: Config, spec: Mapping[str, Any]) -> tuple[str, float]:
    """(how a backbone is made, epoch × train frame of its pretraining)."""
    objective, epochs = _pretraining(c, spec)
    return objective, epochs * _train_rows(c, c["features"]["pretrain"]["corpus"])


def _pretraining_flops(c: Config, spec: Mapping[str, Any]) -> float:
    """FLOPs of a backbone's pretraining: its frame-epochs in forwards of its arch (DINO's or
    MAE's count per frame and epoch)."""
    objective, units = _pretraining_units(c, spec)
    forwards = _MAE_FORWARDS if objective == "mae" else _DINO_FORWARDS
    return units * forwards * _arch_flops(spec["arch"], c["features"]["image_size"])


def _family_spec(c: Config, w: Wildcards) -> Mapping[str, Any]:
    return c["backbones"]["families"][w["family"]][w["modality"]]


def _family_corpora(c: Config) -> list[str]:
    fams = c["probes"]["families"]
    return sorted({fams[p]["corpus"] for p in c["backbones"]["probes"]})


def _family_frames(c: Config) -> float:
    """Frames a family backbone extracts: every frame of the probe corpora."""
    return sum(_n(c, k) for k in _family_corpora(c))


def _simulated_rows(c: Mapping[str, Any]) -> float:
    """Rows of the corpora the visibility check reads: every simulated corpus of a config and
    the first corpus of the regime's rho grid (rules/features.smk, VISIBILITY_CORPORA)."""
    grid = list(regime_corpora(c.get("regime")).items())[:1]
    corpora = {**c["corpora"], **dict(grid)}
    return float(sum(int(v.get("n", 0)) for v in corpora.values() if v.get("kind") == "simulated"))


def _family_backbone(c: Config, w: Wildcards) -> tuple[str, float]:
    """One family backbone: its pretraining (epoch × train frame, MAE or DINO; none for the
    random init or a checkpoint) and the frames of the probe corpora it extracts. Class: the
    objective; a checkpoint's job is priced as the random init's (the same job: a backbone
    made without training, then extraction, whose FLOPs are counted by its arch)."""
    objective, units = _pretraining_units(c, _family_spec(c, w))
    return ("random" if objective == "checkpoint" else objective), units + _family_frames(c)


def _family_backbone_flops(c: Config, w: Wildcards) -> float:
    spec = _family_spec(c, w)
    extraction = _family_frames(c) * _arch_flops(spec["arch"], c["features"]["image_size"])
    return _pretraining_flops(c, spec) + extraction


#: DINO self-distillation per frame and epoch, in ViT forwards: 2 global crops through the
#: student (forward + backward = 3 forwards) and the teacher (1), local crops left out.
_DINO_FORWARDS = 8


def _align_cells(c: Config) -> float:
    a = c["align"]
    return float(
        len(a["corpora"])
        * len(a["variants"])
        * len(a["seeds"])
        * len(a["taus"])
        * len(a["n_train"])
    )


def _align_steps(c: Config, w: Wildcards) -> float:
    """Optimiser steps of one alignment cell at most (`budget` epochs or steps)."""
    a = c["align"]
    rows = _train_rows(c, w["corpus"])
    if w["n_train"] != "all":
        rows = min(rows, float(w["n_train"]))
    if a["budget"] == "steps":
        return float(a["steps"])
    return float(a["epochs"]) * max(1.0, rows // int(a["batch_size"]))


def _generator_mlp(c: Config) -> float:
    """FLOPs of one row through the residual MLP forward (2 hidden² layers per block, plus the
    input and output layers of ~3 × 768-d features)."""
    g = c["generate"]
    h = int(g["hidden"])
    return 2.0 * (int(g["blocks"]) * 2 * h * h + 3 * 768 * h)


def _baseline_targets(c: Config, corpus: str) -> set[str]:
    """The targets of a corpus's generator baselines: the latent generator's and the pixel
    generators' (rules/generate_common.smk, BASELINE_TARGETS)."""
    pixel = ((c.get("pixel") or {}).get("corpora") or {}).get(corpus, {})
    return set(c["generate"]["corpora"].get(corpus, {})) | set(pixel)


def _pixel_frame(c: Config) -> float:
    """Pixels of the pixel generators' frames (`pixel.size`)."""
    h, w = c["pixel"]["size"]
    return float(h) * float(w)


def _pixel_forward(c: Config, generator: str) -> float:
    """Approximate FLOPs of one frame through a pixel generator's forward: per U-Net level of
    the frame's 1/4**level pixels, its convolutions (Pix2Pix: a 4 x 4 down and up convolution
    per width; the DDPM's U-Net: two 3 x 3 convolutions per ResNet block, layers_per_block
    down and one more up, a skip concatenation doubling the up blocks' inputs), multiply-add
    = 2. An estimate for pricing bigger models, not a count of every operation."""
    px = _pixel_frame(c)
    if generator == "pix2pix":
        ch = [3, *(int(x) for x in c["pixel"]["pix2pix"]["channels"])]
        enc = sum(px / 4 ** (i + 1) * 16 * ch[i] * ch[i + 1] for i in range(len(ch) - 1))
        disc = [6, *(int(x) for x in c["pixel"]["pix2pix"]["disc_channels"])]
        d = sum(px / 4 ** (i + 1) * 16 * disc[i] * disc[i + 1] for i in range(len(disc) - 1))
        return 2.0 * (3 * enc + d)  # decoder ~ 2 x encoder (skip inputs), + the discriminator
    d = c["pixel"]["ddpm"]
    ch, lpb = [int(x) for x in d["channels"]], int(d["layers_per_block"])
    total = 0.0
    for level, width in enumerate(ch):
        per_block = 2 * 9 * width * width * px / 4**level
        total += per_block * (lpb + (lpb + 1) * 1.5)  # down blocks; up blocks with skips
    return 2.0 * total


def _pixel_steps(w: Wildcards) -> float:
    """Sampling steps of a pixel arm: its DDIM steps, 1 for Pix2Pix."""
    arm = w["arm"]
    return 1.0 if arm == "pix2pix" else float(arm.removesuffix("_cal").rsplit("_s", 1)[1])


def _pixel_passes(w: Wildcards) -> int:
    arm = w["arm"]
    if arm == "pix2pix":
        return 1
    return len(guidance_passes(arm.removeprefix("ddpm_w").rsplit("_s", 1)[0]))


def _sample_cells(c: Config, w: Wildcards) -> list[tuple[float, float]]:
    """(units, FLOPs) of each sampling cell of one generator (rule sample_generator): sample ×
    sampling step, and the MLP's FLOPs × the passes its guidance needs."""
    g = c["generate"]
    n, mlp = _n(c, w["corpus"]), _generator_mlp(c)
    return [
        (n * int(steps), len(guidance_passes(guidance)) * n * int(steps) * mlp)
        for steps_list in g["samplers"].values()
        for steps in steps_list
        for guidance in g["guidance"]
    ]


def _generate_cells(c: Config) -> float:
    g = c["generate"]
    return float(len(g["guidance"]) * sum(len(s) for s in g["samplers"].values()))


def _probe_work(c: Config, w: Wildcards) -> tuple[str, float]:
    """One probe job: rows × fits. Fits = inputs × CV grid × folds (the regulariser search of
    each compared input) + control refits (permutations, label permutations, random draws,
    train resamples) when the protocol runs controls + bootstrap resamples / 100 (a resample
    re-scores, it does not refit). Class: solver kind / protocol variant."""
    p = c["probes"]
    fam = p["families"][w["family"]]
    rob = p.get("robustness", {})
    protocol = w["protocol"]
    raw = protocol == "raw"
    aligned = len(c["align"]["seeds"]) if fam.get("vision", "vit") == "vit" else 0
    if raw or rob.get("comparisons", "headline") == "all":
        inputs = 1 + len(p["fusions"]) * (1 + aligned) + len(c["preprocess"]["variants"])
    else:
        inputs = 2
    if protocol == "mlp2":
        mlp = rob["mlp"]
        grid = len(mlp["widths"]) * len(mlp["weight_decays"]) * int(mlp["folds"])
    else:
        grid = len(p["lambdas"] if fam["kind"] == "ridge" else p["C"]) * int(p["folds"])
    controls = raw or bool(rob.get("controls", False))
    refits = (
        int(p["permutations"]) + int(p["label_permutations"]) + int(p["random_draws"])
        if controls
        else 0
    ) + (int(p["train_resamples"]) if raw else 0)
    work = inputs * grid + refits + int(p["bootstrap"]) / 100
    return f"{fam['kind']}/{protocol}", _n(c, fam["corpus"]) * work


def _probe_jobs(c: Config) -> float:
    p = c["probes"]
    rob = p.get("robustness", {})
    other = len([x for x in rob.get("protocols", []) if x != "raw"])
    return float(len(p["seeds"]) * (len(p["families"]) + other * len(rob.get("families", []))))


def _policy(c: Config) -> Mapping[str, Any]:
    return c.get("policy", {})


def _episodes(c: Config, episode_set: str) -> float:
    pol = _policy(c)
    return float(pol.get("n_demos" if episode_set == "demos" else "n_heldout", 0))


def _policy_cells(c: Config) -> float:
    pol = _policy(c)
    return float(
        len(pol.get("seeds", [1])) * 4
        + len(pol.get("sweep_hidden", [])) * len(pol.get("sweep_epochs", []))
        + 2
    )


def _const(unit: str) -> UnitRule:
    """A rule whose jobs are all alike: one unit each, so its cost is its overhead."""
    return UnitRule(unit, lambda c, w: ("", 1.0))


# ---- the table: one line per rule --------------------------------------------------------------

UNITS: dict[str, UnitRule] = {
    # corpus
    "simulate_corpus": UnitRule(
        "sample-press (samples in the shard × presses × tactile pixels / 120×160)",
        lambda c, w: (
            "",
            _n(c, w["corpus"])
            / int(_corpus(c, w["corpus"])["shards"])
            * _presses(c, w["corpus"])
            * _tactile_pixels(c, w["corpus"]),
        ),
    ),
    "simulate_natural_grid": UnitRule(
        "sample-press of the shard + an RGB render per corpus of the regime's rho grid",
        lambda c, w: ("", _natural_grid_units(c)),
    ),
    "merge_corpus": UnitRule("sample", lambda c, w: ("", _n(c, w["corpus"]))),
    "ingest_tvl": _const("job (real corpus; size not in config)"),
    "fuse_manifest": UnitRule(
        "sample (all corpora)", lambda c, w: ("", sum(map(lambda k: _n(c, k), c["corpora"])))
    ),
    "make_splits": UnitRule(
        "sample (all corpora)", lambda c, w: ("", sum(map(lambda k: _n(c, k), c["corpora"])))
    ),
    # preprocess
    "background_subtract": UnitRule(
        "frame × tactile pixels / 120×160",
        lambda c, w: ("", _n(c, w["corpus"]) * _tactile_pixels(c, w["corpus"])),
    ),
    # features
    "pretrain_backbone": UnitRule(
        "epoch × train frame (+ ViT FLOPs)",
        lambda c, w: ("", _pretraining_units(c, c["features"]["backbones"][w["modality"]])[1]),
        lambda c, w: _pretraining_flops(c, c["features"]["backbones"][w["modality"]]),
    ),
    "extract_vision_features": UnitRule(
        "frame (+ ViT FLOPs)",
        lambda c, w: ("", _n(c, w["corpus"])),
        lambda c, w: _n(c, w["corpus"]) * _backbone(c, "vision"),
    ),
    "extract_tactile_features": UnitRule(
        "frame (+ ViT FLOPs)",
        lambda c, w: ("", _n(c, w["corpus"])),
        lambda c, w: _n(c, w["corpus"]) * _backbone(c, "tactile"),
    ),
    "share_natural_vision": UnitRule(
        "frame (compared byte for byte with both ends'; its features copied)",
        lambda c, w: ("", _n(c, w["corpus"])),
    ),
    "share_natural_touch": UnitRule(
        "frame (compared byte for byte; its features copied)",
        lambda c, w: ("", _n(c, w["corpus"])),
    ),
    "pretrained_vs_random": UnitRule(
        "frame (+ FLOPs of both random-init ViTs)",
        lambda c, w: ("", _n(c, c["features"]["pretrained_vs_random"]["corpus"])),
        lambda c, w: (
            _n(c, c["features"]["pretrained_vs_random"]["corpus"])
            * (_backbone(c, "vision") + _backbone(c, "tactile"))
        ),
    ),
    # align
    "train_heads": UnitRule(
        "optimiser step × batch row (at most; early stopping ends sooner)",
        lambda c, w: ("", _align_steps(c, w) * int(c["align"]["batch_size"])),
    ),
    "project_aligned": UnitRule(
        "sample of the target corpus", lambda c, w: ("", _n(c, w["target"]))
    ),
    "aggregate_align": UnitRule("grid cell", lambda c, w: ("", _align_cells(c))),
    # generate
    "train_generator": UnitRule(
        "optimiser step (at most; + MLP FLOPs)",
        lambda c, w: ("", float(c["generate"]["steps"])),
        lambda c, w: (
            3.0 * int(c["generate"]["steps"]) * int(c["generate"]["batch_size"]) * _generator_mlp(c)
        ),
    ),
    "sample_generator": UnitRule(
        "sample × sampling step, every cell of the generator (+ MLP FLOPs × the passes "
        "guidance w needs: 1 at w = 0, 1; else 2)",
        lambda c, w: ("", sum(u for u, _ in _sample_cells(c, w))),
        lambda c, w: sum(f for _, f in _sample_cells(c, w)),
        cells=_sample_cells,
        on_gpu=False,  # sampled in numpy (tacgen_lib.generate.inference)
    ),
    "fit_generator_baselines": UnitRule(
        "sample × target (3 CV probes + one per nonlinear gamma)",
        lambda c, w: (
            "",
            _n(c, w["corpus"])
            * len(_baseline_targets(c, w["corpus"]))
            * (2 + len(c["generate"]["nonlinear_gammas"])),
        ),
    ),
    "evaluate_generator": UnitRule(
        "sample × (sampling cells × targets + permutations / 100)",
        lambda c, w: (
            "",
            _n(c, w["corpus"])
            * (
                _generate_cells(c) * len(c["generate"]["corpora"][w["corpus"]])
                + int(c["generate"]["permutations"]) / 100
            ),
        ),
    ),
    "aggregate_generate": UnitRule(
        "sampling cell (all generators)",
        lambda c, w: (
            "",
            _generate_cells(c) * len(c["generate"]["corpora"]) * len(c["generate"]["seeds"]),
        ),
    ),
    # regime (where generated touch helps)
    "regime_generators": UnitRule(
        "optimiser step × pool size × pairing (at most; + MLP FLOPs)",
        lambda c, w: ("", float(c["regime"]["steps"]) * 2 * len(c["regime"]["n_pool"])),
        lambda c, w: (
            3.0
            * int(c["regime"]["steps"])
            * int(c["regime"]["batch_size"])
            * 2
            * len(c["regime"]["n_pool"])
            * _generator_mlp(c)
        ),
    ),
    "regime_evaluate": UnitRule(
        "(labelled + pool rows) × target × labelled size × pool size × labelled draw",
        lambda c, w: (
            "",
            (max(c["regime"]["n_labelled"]) + max(c["regime"]["n_pool"]))
            * len(c["regime"]["targets"])
            * len(c["regime"]["n_labelled"])
            * len(c["regime"]["n_pool"])
            * int(c["regime"].get("label_draws", 1)),
        ),
    ),
    "visibility_check": UnitRule(
        "row of every simulated corpus (each factor's two probes)",
        lambda c, w: ("", _simulated_rows(c)),
    ),
    "aggregate_regime": UnitRule(
        "corpus × seed",
        lambda c, w: ("", len(c["regime"]["rhos"]) * len(c["regime"]["seeds"])),
    ),
    # backbone families
    "family_backbone": UnitRule(
        "epoch × train frame (pretraining) + frame extracted (+ FLOPs)",
        _family_backbone,
        _family_backbone_flops,
    ),
    "family_probe": UnitRule(
        "row × probe family × protocol",
        lambda c, w: (
            "",
            sum(_n(c, c["probes"]["families"][p]["corpus"]) for p in c["backbones"]["probes"])
            * len(c["backbones"].get("protocols", ["raw", "mlp2"])),
        ),
    ),
    "cost_backbone_points": UnitRule(
        "family run", lambda c, w: ("", float(len(c["backbones"]["run"])))
    ),
    "aggregate_backbones": UnitRule(
        "family run", lambda c, w: ("", float(len(c["backbones"]["run"])))
    ),
    # transfer to a second sensor: every probe seed fits V, V+T and shuffled V+T per heads view
    # pixel generators
    "train_pixel_generator": UnitRule(
        "optimiser step × batch × frame pixel (at most; + conv FLOPs), per generator",
        lambda c, w: (
            w["generator"],
            float(c["pixel"][w["generator"]]["steps"])
            * int(c["pixel"][w["generator"]]["batch_size"])
            * _pixel_frame(c),
        ),
        lambda c, w: (
            3.0
            * int(c["pixel"][w["generator"]]["steps"])
            * int(c["pixel"][w["generator"]]["batch_size"])
            * _pixel_forward(c, w["generator"])
        ),
    ),
    "sample_pixel_generator": UnitRule(
        "sample × sampling step (Pix2Pix: 1) × frame pixel (+ conv FLOPs × guidance passes)",
        lambda c, w: (
            "pix2pix" if w["arm"] == "pix2pix" else "ddpm",
            _n(c, w["corpus"]) * _pixel_steps(w) * _pixel_frame(c),
        ),
        lambda c, w: (
            _pixel_passes(w)
            * _n(c, w["corpus"])
            * _pixel_steps(w)
            * _pixel_forward(c, "pix2pix" if w["arm"] == "pix2pix" else "ddpm")
        ),
    ),
    "evaluate_pixel_generators": UnitRule(
        "sample × (arm, calibrated or not, + the real reference) × target",
        lambda c, w: (
            "",
            _n(c, w["corpus"])
            * (
                2
                * (
                    1
                    + len(c["pixel"]["ddpm_cells"]["guidance"])
                    * len(c["pixel"]["ddpm_cells"]["steps"])
                )
                + 1
            )
            * len(c["pixel"]["corpora"][w["corpus"]]),
        ),
    ),
    "pixel_curve_point": UnitRule(
        "sample × heads trained (1 at p = 0, else generated + shuffled)",
        lambda c, w: ("", _n(c, w["corpus"]) * (1.0 if float(w["fraction"]) == 0 else 2.0)),
    ),
    "aggregate_pixel": UnitRule(
        "judged corpus × seed + curve point",
        lambda c, w: (
            "",
            float(
                len(c["pixel"]["corpora"]) * len(c["pixel"]["seeds"])
                + len(c["pixel"]["curve"]["corpora"]) * len(c["pixel"]["curve"]["fractions"])
            ),
        ),
    ),
    "transfer_evaluate": UnitRule(
        "contact × probe seed × heads view",
        lambda c, w: (
            "",
            _n(c, c["transfer"]["corpus"]) * len(c["transfer"]["probe_seeds"]) * 4.0,
        ),
    ),
    # language
    "language_evidence": UnitRule("sample of the corpus", lambda c, w: ("", _n(c, w["corpus"]))),
    "aggregate_language": UnitRule(
        "generator corpus", lambda c, w: ("", float(len(c["generate"]["corpora"])))
    ),
    # probes
    "probe": UnitRule("row × fit (inputs × CV grid + control refits)", _probe_work),
    "probe_training_size": UnitRule(
        "row × training size × subset seed",
        lambda c, w: (
            "",
            _n(c, c["probes"]["families"][w["family"]]["corpus"])
            * len(c["probes"]["robustness"]["training_size"]["n_train"])
            * len(c["probes"]["robustness"]["training_size"]["seeds"]),
        ),
    ),
    "probe_within_scale": UnitRule(
        "row × protocol variant",
        lambda c, w: (
            "",
            _n(c, c["probes"]["families"][w["family"]]["corpus"])
            * len(c["probes"]["robustness"]["protocols"]),
        ),
    ),
    "aggregate_probes": UnitRule("probe job", lambda c, w: ("", _probe_jobs(c))),
    "aggregate_robustness": UnitRule("probe job", lambda c, w: ("", _probe_jobs(c))),
    # policy
    "collect_demos": UnitRule(
        "episode in the shard",
        lambda c, w: (
            "",
            _episodes(c, w["episode_set"]) / int(_policy(c).get("collect_shards", 1)),
        ),
    ),
    "palpate": UnitRule(
        "episode (+ V and T ViT FLOPs)",
        lambda c, w: ("", _episodes(c, "demos") + _episodes(c, "heldout")),
        lambda c, w: (
            (_episodes(c, "demos") + _episodes(c, "heldout"))
            * (_backbone(c, "vision") + _backbone(c, "tactile"))
        ),
    ),
    "train_policy": UnitRule(
        "epoch × demo (+ MLP FLOPs)",
        lambda c, w: ("", int(w["epochs"]) * _episodes(c, "demos")),
        lambda c, w: 6.0 * int(w["epochs"]) * _episodes(c, "demos") * 3 * int(w["hidden"]) ** 2,
    ),
    "rollout_policy": UnitRule(
        "held-out episode in the shard",
        lambda c, w: (
            "",
            _episodes(c, "heldout") / int(_policy(c).get("rollout_shards", 1)),
        ),
    ),
    "policy_regression": UnitRule(
        "episode", lambda c, w: ("", _episodes(c, "demos") + _episodes(c, "heldout"))
    ),
    "aggregate_policy": UnitRule(
        "policy cell × bootstrap resample / 1000",
        lambda c, w: ("", _policy_cells(c) * int(_policy(c).get("bootstrap", 1000)) / 1000),
    ),
    # report
    "corpus_examples": UnitRule(
        "example frame", lambda c, w: ("", float(c["report"]["examples_per_corpus"]))
    ),
    "edge_manifest": _const("job"),
    "pretrain_curve": _const("job"),
    "findings": _const("job"),
    "cost_of_accuracy": _const("job"),
    # cost of accuracy: the knobs' settings are the main rules' jobs under the setting's config
    # (tacgen_lib.cost.knobs); what remains is reading points, the same kind of job everywhere
    "cost_knob_points": UnitRule(
        "job (priced as cost_generate_points: a points job)",
        lambda c, w: ("", 1.0),
        same_as="cost_generate_points",
    ),
    "cost_generate_points": _const("job"),
    "cost_policy_points": _const("job"),
}


def job_units(rule: str, config: Config, wildcards: Wildcards) -> tuple[str, float, float]:
    """(cost class, units, FLOPs) of one job of `rule` (FLOPs 0 for a rule without a model). A rule without a line in `UNITS`, or whose
    line cannot count this config, raises `MissingUnitsError` naming the rule."""
    if rule not in UNITS:
        raise MissingUnitsError(
            f"rule {rule!r} has no unit definition: add a line for it to "
            "tacgen_lib/runtime/units.py UNITS, then regenerate the calibration "
            "(python -m tacgen_lib.runtime.calibration)"
        )
    try:
        suffix, units = UNITS[rule].count(config, wildcards)
        flops = UNITS[rule].flops(config, wildcards) if UNITS[rule].flops else 0.0
    except (KeyError, TypeError, ValueError, ZeroDivisionError) as exc:
        raise MissingUnitsError(
            f"rule {rule!r}: cannot count its units ({UNITS[rule].unit}) for wildcards "
            f"{dict(wildcards)} from this config ({type(exc).__name__}: {exc}); fix its line in "
            "tacgen_lib/runtime/units.py UNITS"
        ) from exc
    name = UNITS[rule].same_as or rule
    return (f"{name}:{suffix}" if suffix else name), float(units), float(flops)


def flop_seconds(flops: float, threads: int) -> float:
    """Seconds of `flops` at the effective GEMM rate of `threads` threads."""
    return flops / (GFLOPS_PER_THREAD * 1e9 * max(1, threads))
