"""What a config asks of each stage, for the run-time estimate: its corpora's samples, presses
and pixels, training rows and optimiser steps, pretraining epochs, grid cells, probe fits,
policy episodes, read from the merged config and a job's wildcards. The lines of
`tacgen_lib.estimate.units.UNITS` multiply these into each rule's units of work.

The config is the validated one (`tacgen_lib.workflow_config.validate_config`: the schema's
defaults filled), as the workflow reads it: a setting is read, never given a default here.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

from tacgen_lib.corpus.ingest_plan import listed_rows
from tacgen_lib.estimate.flops import (
    DINO_FORWARDS,
    MAE_FORWARDS,
    SIMCLR_FORWARDS,
    generator_mlp_flops,
    spec_flops,
)
from tacgen_lib.features.settings import MaeSettings, SimclrSettings, pretraining_corpora
from tacgen_lib.generate.regime_sets import RegimeSettings, pool_steps, regime_corpora
from tacgen_lib.generate.sampling_cells import guidance_passes
from tacgen_lib.generate.settings import baseline_targets as generate_baseline_targets
from tacgen_lib.io.config import load_yaml

Config = Mapping[str, Any]
Wildcards = Mapping[str, str]


def corpus_of(c: Config, name: str) -> Mapping[str, Any]:
    return c["corpora"][name]


@functools.cache
def scene_effects(scenes_file: str) -> dict[str, tuple[str, ...]]:
    """Scene name -> its declared effects, read once from the scenes file ({} if absent)."""
    try:
        scenes = load_yaml(scenes_file) or {}
    except FileNotFoundError:
        return {}
    return {name: tuple(decl.get("effects", ())) for name, decl in scenes.items()}


def presses(c: Config, name: str) -> float:
    """Presses a simulated sample costs: its jittered presses (`presses`) where its scene
    declares press_jitter, else the one nominal press. A scenes file not found from here (the
    estimate run from another folder than the workflow's) prices the jittered presses."""
    corpus = corpus_of(c, name)
    effects = scene_effects(str(c["scenes_file"])).get(str(corpus["scene"]), ("press_jitter",))
    return float(corpus["presses"]) if "press_jitter" in effects else 1.0


def natural_grid_units(c: Config) -> float:
    """A shard of the regime's rho grid (rule simulate_natural_grid): its samples × (presses ×
    tactile pixels, once for the grid + one render per corpus of the grid)."""
    grid = regime_corpora(c.get("regime"))
    first = next(iter(grid))
    c = {**c, "corpora": {**c["corpora"], **grid}}  # the DAG joins them too
    per_sample = presses(c, first) * tactile_pixels(c, first) + len(grid)
    return samples(c, first) / int(corpus_of(c, first)["shards"]) * per_sample


def regime_pool_steps(c: Config) -> float:
    """The step caps of a regime seed's generators, one per pool size of config ``regime``
    (`regime_sets.pool_steps`: larger pools train longer), summed over the pool sizes."""
    regime = RegimeSettings.from_config(c["regime"])
    return float(sum(pool_steps(regime.steps, int(n), regime) for n in regime.n_pool))


def regime_cell_rows(c: Config) -> float:
    """The rows a regime job's arms are fitted over, summed over its cells: per pool size, the
    largest labelled set plus the pool (the ladder's rungs learn from the pool), times the
    targets, labelled sizes and labelled draws of config ``regime``. A sum over the pool
    sizes, not the largest pool times their number: a grid of pools from 256 to 16,384 rows
    costs about its largest pool's cells, not four times them."""
    regime = c["regime"]
    per_pool = sum(max(regime["n_labelled"]) + int(n) for n in regime["n_pool"])
    return float(
        per_pool * len(regime["targets"]) * len(regime["n_labelled"]) * int(regime["label_draws"])
    )


def samples(c: Config, name: str) -> float:
    """Samples of a corpus: `n` of a simulated one; for a real one, the rows its dataset's
    split CSVs list (`tacgen_lib.corpus.ingest.listed_rows`, counted on disk without opening
    an image), 1 where its folder is not there."""
    corpus = corpus_of(c, name)
    if corpus["kind"] in ("ssvtp", "hct"):
        return float(listed_rows(str(corpus["kind"]), str(corpus["root"])) or 1)
    return float(corpus["n"])


def tactile_pixels(c: Config, name: str) -> float:
    """Tactile pixels of a simulated corpus's frames relative to 120 × 160 (1 for a real one)."""
    corpus = corpus_of(c, name)
    if corpus["kind"] != "simulated":
        return 1.0
    h, w = corpus["tactile_size"]
    return float(h) * float(w) / (120.0 * 160.0)


def train_rows(c: Config, name: str) -> float:
    return samples(c, name) * float(c["splits"]["fractions"]["train"])


def pretraining(c: Config, spec: Mapping[str, Any]) -> tuple[str, int]:
    """(how a backbone is made, its pretraining epochs): "checkpoint" and "random" train
    nothing; "dino" runs features.pretrain.epochs, "mae" features.mae.epochs, "simclr"
    features.simclr.epochs."""
    if spec["checkpoint"]:
        return "checkpoint", 0
    objective = spec["objective"]
    if objective == "mae":
        return objective, MaeSettings.from_config(c["features"]["mae"]).epochs
    if objective == "simclr":
        return objective, SimclrSettings.from_config(c["features"]["simclr"]).epochs
    if objective == "dino":
        return objective, int(c["features"]["pretrain"]["epochs"])
    return objective, 0


def pretraining_units(c: Config, spec: Mapping[str, Any]) -> tuple[str, float]:
    """(how a backbone is made, epoch × train frame of its pretraining)."""
    objective, epochs = pretraining(c, spec)
    corpora = pretraining_corpora(c["features"]["pretrain"])
    return objective, epochs * sum(train_rows(c, name) for name in corpora)


def pretraining_flops(c: Config, spec: Mapping[str, Any]) -> float:
    """FLOPs of a backbone's pretraining: its frame-epochs in forwards of its arch (DINO's or
    MAE's or SimCLR's count per frame and epoch)."""
    objective, units = pretraining_units(c, spec)
    forwards = {"mae": MAE_FORWARDS, "simclr": SIMCLR_FORWARDS}.get(objective, DINO_FORWARDS)
    return units * forwards * spec_flops(c, spec)


def family_spec(c: Config, w: Wildcards) -> Mapping[str, Any]:
    return c["backbones"]["families"][w["family"]][w["modality"]]


def family_corpora(c: Config) -> list[str]:
    fams = c["probes"]["families"]
    return sorted({fams[p]["corpus"] for p in c["backbones"]["probes"]})


def family_frames(c: Config) -> float:
    """Frames a family backbone extracts: every frame of the probe corpora."""
    return sum(samples(c, k) for k in family_corpora(c))


def simulated_rows(c: Mapping[str, Any]) -> float:
    """Rows of the corpora the visibility check reads: every simulated corpus of a config and
    the first corpus of the regime's rho grid (rules/features.smk, VISIBILITY_CORPORA)."""
    grid = list(regime_corpora(c.get("regime")).items())[:1]
    corpora = {**c["corpora"], **dict(grid)}
    return float(sum(int(v["n"]) for v in corpora.values() if v["kind"] == "simulated"))


def family_backbone(c: Config, w: Wildcards) -> tuple[str, float]:
    """One family backbone: its pretraining (epoch × train frame, MAE or DINO; none for the
    random init or a checkpoint) and the frames of the probe corpora it extracts. Class: the
    objective; a checkpoint's job is priced as the random init's (the same job: a backbone
    made without training, then extraction, whose FLOPs are counted by its arch)."""
    objective, units = pretraining_units(c, family_spec(c, w))
    return ("random" if objective == "checkpoint" else objective), units + family_frames(c)


def family_backbone_flops(c: Config, w: Wildcards) -> float:
    spec = family_spec(c, w)
    extraction = family_frames(c) * spec_flops(c, spec)
    return pretraining_flops(c, spec) + extraction


def align_cells(c: Config) -> float:
    a = c["align"]
    return float(
        len(a["corpora"])
        * len(a["variants"])
        * len(a["seeds"])
        * len(a["taus"])
        * len(a["n_train"])
    )


def align_steps(c: Config, w: Wildcards) -> float:
    """Optimiser steps of one alignment cell at most (`budget` epochs or steps)."""
    a = c["align"]
    rows = train_rows(c, w["corpus"])
    if w["n_train"] != "all":
        rows = min(rows, float(w["n_train"]))
    if a["budget"] == "steps":
        return float(a["steps"])
    return float(a["epochs"]) * max(1.0, rows // int(a["batch_size"]))


def baseline_targets(c: Config, corpus: str) -> set[str]:
    """The targets of a corpus's generator baselines (`generate.settings.baseline_targets`)."""
    return set(generate_baseline_targets(c).get(corpus, {}))


def pixel_steps(w: Wildcards) -> float:
    """Sampling steps of a pixel arm: its DDIM steps, 1 for Pix2Pix."""
    arm = w["arm"]
    return 1.0 if arm == "pix2pix" else float(arm.removesuffix("_cal").rsplit("_s", 1)[1])


def pixel_passes(w: Wildcards) -> int:
    arm = w["arm"]
    if arm == "pix2pix":
        return 1
    return len(guidance_passes(arm.removeprefix("ddpm_w").rsplit("_s", 1)[0]))


def sample_cells(c: Config, w: Wildcards) -> list[tuple[float, float]]:
    """(units, FLOPs) of each sampling cell of one generator (rule sample_generator): sample ×
    sampling step, and the MLP's FLOPs × the passes its guidance needs."""
    g = c["generate"]
    n, mlp = samples(c, w["corpus"]), generator_mlp_flops(c)
    return [
        (n * int(steps), len(guidance_passes(guidance)) * n * int(steps) * mlp)
        for steps_list in g["samplers"].values()
        for steps in steps_list
        for guidance in g["guidance"]
    ]


def generate_cells(c: Config) -> float:
    g = c["generate"]
    return float(len(g["guidance"]) * sum(len(s) for s in g["samplers"].values()))


def probe_work(c: Config, w: Wildcards) -> tuple[str, float]:
    """One probe job: rows × fits. Fits = inputs × CV grid × folds (the regulariser search of
    each compared input) + control refits (permutations, label permutations, random draws,
    train resamples) when the protocol runs controls + bootstrap resamples / 100 (a resample
    re-scores, it does not refit). Class: solver kind / protocol variant."""
    p = c["probes"]
    fam = p["families"][w["family"]]
    rob = p["robustness"]
    protocol = w["protocol"]
    raw = protocol == "raw"
    aligned = len(c["align"]["seeds"]) if fam["vision"] == "vit" else 0
    if raw or rob["comparisons"] == "all":
        inputs = 1 + len(p["fusions"]) * (1 + aligned) + len(c["preprocess"]["variants"])
    else:
        inputs = 2
    if protocol == "mlp2":
        mlp = rob["mlp"]
        grid = len(mlp["widths"]) * len(mlp["weight_decays"]) * int(mlp["folds"])
    else:
        grid = len(p["lambdas"] if fam["kind"] == "ridge" else p["C"]) * int(p["folds"])
    controls = raw or bool(rob["controls"])
    refits = (
        int(p["permutations"]) + int(p["label_permutations"]) + int(p["random_draws"])
        if controls
        else 0
    ) + (int(p["train_resamples"]) if raw else 0)
    work = inputs * grid + refits + int(p["bootstrap"]) / 100
    return f"{fam['kind']}/{protocol}", samples(c, fam["corpus"]) * work


def probe_jobs(c: Config) -> float:
    p = c["probes"]
    rob = p["robustness"]
    other = len([x for x in rob["protocols"] if x != "raw"])
    return float(len(p["seeds"]) * (len(p["families"]) + other * len(rob["families"])))


def policy_of(c: Config) -> Mapping[str, Any]:
    return c["policy"]


def episodes(c: Config, episode_set: str) -> float:
    pol = policy_of(c)
    return float(pol["n_demos" if episode_set == "demos" else "n_heldout"])


def policy_cells(c: Config) -> float:
    pol = policy_of(c)
    return float(len(pol["seeds"]) * 4 + len(pol["sweep_hidden"]) * len(pol["sweep_epochs"]) + 2)
