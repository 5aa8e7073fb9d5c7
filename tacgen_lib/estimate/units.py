"""The work units of each rule's jobs: the one table the run-time estimate is built on.

A job's predicted wall time is `overhead + cost_per_unit × units + FLOPs / rate`
(tacgen_lib.estimate.calibration fits the first two per cost class on benchmark files; the
FLOP term, for rules with a model, is charged at the CPU's effective GEMM rate:
tacgen_lib.estimate.flops). `UNITS` has one line per rule: what one unit is, and how many a
job has (its counts: tacgen_lib.estimate.counts), read from the merged config and the job's wildcards. A rule may split
its jobs into cost classes (a probe family's solver kind and protocol variant cost differently
per row); a class is `rule` or `rule:<what>`.

The counts are proportional to the work the job's code does (rows × steps × model size), not
exact: early stopping (align `patience`, generator `patience`) can end training before its
budget, so those rules' predictions are upper-side. Changing a rule's code or its config keys
may change its units: edit its line here, then regenerate the shipped calibration
(`python -m tacgen_lib.estimate.calibration`, README "Run-time estimate").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from tacgen_lib.estimate.counts import (
    Config,
    Wildcards,
    align_cells,
    align_steps,
    baseline_targets,
    corpus_of,
    episodes,
    family_backbone,
    family_backbone_flops,
    generate_cells,
    natural_grid_units,
    pixel_passes,
    pixel_steps,
    policy_cells,
    policy_of,
    presses,
    pretraining_flops,
    pretraining_units,
    probe_jobs,
    probe_work,
    regime_cell_rows,
    regime_pool_steps,
    sample_cells,
    samples,
    simulated_rows,
    tactile_pixels,
)
from tacgen_lib.estimate.flops import (
    backbone_flops,
    generator_mlp_flops,
    pixel_forward_flops,
    pixel_frame,
)

__all__ = ["UnitRule", "UNITS", "job_units", "MissingUnitsError"]


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
    rate (`tacgen_lib.estimate.flops.GFLOPS_PER_THREAD`), so a bigger model costs more without a fitted term for it.
    `same_as`: another rule whose calibration prices these jobs (the same kind of work, where
    this rule never runs in a calibration run).
    `cells(config, wildcards) -> [(units, FLOPs), ...]`, for a job that runs independent cells
    in one-thread workers, one per thread (`tacgen_lib.runtime.workers.fork_map`): the job's
    units and FLOPs are the cells' sums, and its wall is the overhead plus the longest-first
    schedule of its cells on its threads (`tacgen_lib.estimate.predict.job_prediction`)."""

    unit: str
    count: Callable[[Config, Wildcards], tuple[str, float]]
    flops: Callable[[Config, Wildcards], float] | None = None
    same_as: str | None = None
    cells: Callable[[Config, Wildcards], list[tuple[float, float]]] | None = None
    #: whether its FLOPs run in torch, so on a GPU class (`estimate --gpu-tflops`) at the
    #: GPU's rate; False for numpy arithmetic (the latent generator's sampler)
    on_gpu: bool = True


def _const(unit: str) -> UnitRule:
    """A rule whose jobs are all alike: one unit each, so its cost is its overhead."""
    return UnitRule(unit, lambda c, w: ("", 1.0))


# ---- the table: one line per rule -------------------------------------------------------------

UNITS: dict[str, UnitRule] = {
    # corpus
    "simulate_corpus": UnitRule(
        "sample-press (samples in the shard × presses × tactile pixels / 120×160)",
        lambda c, w: (
            "",
            samples(c, w["corpus"])
            / int(corpus_of(c, w["corpus"])["shards"])
            * presses(c, w["corpus"])
            * tactile_pixels(c, w["corpus"]),
        ),
    ),
    "simulate_natural_grid": UnitRule(
        "sample-press of the shard + an RGB render per corpus of the regime's rho grid",
        lambda c, w: ("", natural_grid_units(c)),
    ),
    "merge_corpus": UnitRule("sample", lambda c, w: ("", samples(c, w["corpus"]))),
    "ingest_tvl": UnitRule(
        "sample (the rows its dataset's split CSVs list)",
        lambda c, w: ("", samples(c, w["corpus"])),
    ),
    "fuse_manifest": UnitRule(
        "sample (all corpora)", lambda c, w: ("", sum(map(lambda k: samples(c, k), c["corpora"])))
    ),
    "make_splits": UnitRule(
        "sample (all corpora)", lambda c, w: ("", sum(map(lambda k: samples(c, k), c["corpora"])))
    ),
    # preprocess
    "background_subtract": UnitRule(
        "frame × tactile pixels / 120×160",
        lambda c, w: ("", samples(c, w["corpus"]) * tactile_pixels(c, w["corpus"])),
    ),
    # features
    "pretrain_backbone": UnitRule(
        "epoch × train frame (+ ViT FLOPs)",
        lambda c, w: ("", pretraining_units(c, c["features"]["backbones"][w["modality"]])[1]),
        lambda c, w: pretraining_flops(c, c["features"]["backbones"][w["modality"]]),
    ),
    "extract_vision_features": UnitRule(
        "frame (+ ViT FLOPs)",
        lambda c, w: ("", samples(c, w["corpus"])),
        lambda c, w: samples(c, w["corpus"]) * backbone_flops(c, "vision"),
    ),
    "extract_tactile_features": UnitRule(
        "frame (+ ViT FLOPs)",
        lambda c, w: ("", samples(c, w["corpus"])),
        lambda c, w: samples(c, w["corpus"]) * backbone_flops(c, "tactile"),
    ),
    "share_natural_vision": UnitRule(
        "frame (compared byte for byte with both ends'; its features copied)",
        lambda c, w: ("", samples(c, w["corpus"])),
    ),
    "share_natural_touch": UnitRule(
        "frame (compared byte for byte; its features copied)",
        lambda c, w: ("", samples(c, w["corpus"])),
    ),
    "pretrained_vs_random": UnitRule(
        "frame (+ FLOPs of both random-init ViTs)",
        lambda c, w: ("", samples(c, c["features"]["pretrained_vs_random"]["corpus"])),
        lambda c, w: (
            samples(c, c["features"]["pretrained_vs_random"]["corpus"])
            * (backbone_flops(c, "vision") + backbone_flops(c, "tactile"))
        ),
    ),
    # align
    "train_heads": UnitRule(
        "optimiser step × batch row (at most; early stopping ends sooner)",
        lambda c, w: ("", align_steps(c, w) * int(c["align"]["batch_size"])),
    ),
    "project_aligned": UnitRule(
        "sample of the target corpus", lambda c, w: ("", samples(c, w["target"]))
    ),
    "aggregate_align": UnitRule("grid cell", lambda c, w: ("", align_cells(c))),
    # generate
    "train_generator": UnitRule(
        "optimiser step (at most; + MLP FLOPs)",
        lambda c, w: ("", float(c["generate"]["steps"])),
        lambda c, w: (
            3.0
            * int(c["generate"]["steps"])
            * int(c["generate"]["batch_size"])
            * generator_mlp_flops(c)
        ),
    ),
    "sample_generator": UnitRule(
        "sample × sampling step, every cell of the generator (+ MLP FLOPs × the passes "
        "guidance w needs: 1 at w = 0, 1; else 2)",
        lambda c, w: ("", sum(u for u, _ in sample_cells(c, w))),
        lambda c, w: sum(f for _, f in sample_cells(c, w)),
        cells=sample_cells,
        on_gpu=False,  # sampled in numpy (tacgen_lib.generate.inference)
    ),
    "fit_generator_baselines": UnitRule(
        "sample × target (3 CV probes + one per nonlinear gamma)",
        lambda c, w: (
            "",
            samples(c, w["corpus"])
            * len(baseline_targets(c, w["corpus"]))
            * (2 + len(c["generate"]["nonlinear_gammas"])),
        ),
    ),
    "evaluate_generator": UnitRule(
        "sample × (sampling cells × targets + permutations / 100)",
        lambda c, w: (
            "",
            samples(c, w["corpus"])
            * (
                generate_cells(c) * len(c["generate"]["corpora"][w["corpus"]])
                + int(c["generate"]["permutations"]) / 100
            ),
        ),
    ),
    "aggregate_generate": UnitRule(
        "sampling cell (all generators)",
        lambda c, w: (
            "",
            generate_cells(c) * len(c["generate"]["corpora"]) * len(c["generate"]["seeds"]),
        ),
    ),
    # regime (where generated touch helps)
    "regime_generators": UnitRule(
        "optimiser step (each pool size's cap) × pairing (at most; + MLP FLOPs)",
        lambda c, w: ("", regime_pool_steps(c) * 2),
        lambda c, w: (
            3.0 * regime_pool_steps(c) * int(c["regime"]["batch_size"]) * 2 * generator_mlp_flops(c)
        ),
    ),
    "regime_evaluate": UnitRule(
        "(labelled + pool rows) × target × labelled size × labelled draw, summed over the pool sizes",
        lambda c, w: ("", regime_cell_rows(c)),
    ),
    # the same script and cells on fewer arms (no ceilings, distillation or generator): priced
    # as regime_evaluate's jobs, an upper bound (it runs only where a curve does, in no
    # calibration run)
    "regime_look_control": UnitRule(
        "(labelled + pool rows) × target × labelled size × labelled draw, summed over the pool sizes",
        lambda c, w: ("", regime_cell_rows(c)),
        same_as="regime_evaluate",
    ),
    "visibility_check": UnitRule(
        "row of every simulated corpus (each factor's probes; the gate's factors' 2-layer probe)",
        lambda c, w: ("", simulated_rows(c)),
    ),
    "aggregate_regime": UnitRule(
        "corpus × seed",
        lambda c, w: ("", len(c["regime"]["rhos"]) * len(c["regime"]["seeds"])),
    ),
    # backbone families
    "family_backbone": UnitRule(
        "epoch × train frame (pretraining) + frame extracted (+ FLOPs)",
        family_backbone,
        family_backbone_flops,
    ),
    "family_probe": UnitRule(
        "row × probe family × protocol",
        lambda c, w: (
            "",
            sum(samples(c, c["probes"]["families"][p]["corpus"]) for p in c["backbones"]["probes"])
            * len(c["backbones"]["protocols"]),
        ),
    ),
    "aggregate_backbones": UnitRule(
        "family run", lambda c, w: ("", float(len(c["backbones"]["run"])))
    ),
    # pixel generators
    "train_pixel_generator": UnitRule(
        "optimiser step × batch × frame pixel (at most; + conv FLOPs), per generator",
        lambda c, w: (
            w["generator"],
            float(c["pixel"][w["generator"]]["steps"])
            * int(c["pixel"][w["generator"]]["batch_size"])
            * pixel_frame(c),
        ),
        lambda c, w: (
            3.0
            * int(c["pixel"][w["generator"]]["steps"])
            * int(c["pixel"][w["generator"]]["batch_size"])
            * pixel_forward_flops(c, w["generator"])
        ),
    ),
    "sample_pixel_generator": UnitRule(
        "sample × sampling step (Pix2Pix: 1) × frame pixel (+ conv FLOPs × guidance passes)",
        lambda c, w: (
            "pix2pix" if w["arm"] == "pix2pix" else "ddpm",
            samples(c, w["corpus"]) * pixel_steps(w) * pixel_frame(c),
        ),
        lambda c, w: (
            pixel_passes(w)
            * samples(c, w["corpus"])
            * pixel_steps(w)
            * pixel_forward_flops(c, "pix2pix" if w["arm"] == "pix2pix" else "ddpm")
        ),
    ),
    "evaluate_pixel_generators": UnitRule(
        "sample × (arm, calibrated or not, + the real reference) × target",
        lambda c, w: (
            "",
            samples(c, w["corpus"])
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
        lambda c, w: ("", samples(c, w["corpus"]) * (1.0 if float(w["fraction"]) == 0 else 2.0)),
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
    # transfer to a second sensor: every probe seed fits V, V+T and shuffled V+T per heads
    # view, the three views with heads once per alignment seed
    "transfer_evaluate": UnitRule(
        "contact × probe seed × heads view",
        lambda c, w: (
            "",
            samples(c, c["transfer"]["corpus"])
            * len(c["transfer"]["probe_seeds"])
            * (1.0 + 3.0 * len(c["align"]["seeds"])),
        ),
    ),
    # language
    "language_evidence": UnitRule(
        "sample of the corpus", lambda c, w: ("", samples(c, w["corpus"]))
    ),
    "aggregate_language": UnitRule(
        "generator corpus", lambda c, w: ("", float(len(c["generate"]["corpora"])))
    ),
    # probes
    "probe": UnitRule("row × fit (inputs × CV grid + control refits)", probe_work),
    "probe_training_size": UnitRule(
        "row × training size × subset seed",
        lambda c, w: (
            "",
            samples(c, c["probes"]["families"][w["family"]]["corpus"])
            * len(c["probes"]["robustness"]["training_size"]["n_train"])
            * len(c["probes"]["robustness"]["training_size"]["seeds"]),
        ),
    ),
    "probe_within_scale": UnitRule(
        "row × protocol variant",
        lambda c, w: (
            "",
            samples(c, c["probes"]["families"][w["family"]]["corpus"])
            * len(c["probes"]["robustness"]["protocols"]),
        ),
    ),
    "aggregate_probes": UnitRule("probe job", lambda c, w: ("", probe_jobs(c))),
    "aggregate_robustness": UnitRule("probe job", lambda c, w: ("", probe_jobs(c))),
    # policy
    "collect_demos": UnitRule(
        "episode in the shard",
        lambda c, w: (
            "",
            episodes(c, w["episode_set"]) / int(policy_of(c)["collect_shards"]),
        ),
    ),
    "palpate": UnitRule(
        "episode (+ V and T ViT FLOPs)",
        lambda c, w: ("", episodes(c, "demos") + episodes(c, "heldout")),
        lambda c, w: (
            (episodes(c, "demos") + episodes(c, "heldout"))
            * (backbone_flops(c, "vision") + backbone_flops(c, "tactile"))
        ),
    ),
    "train_policy": UnitRule(
        "epoch × demo (+ MLP FLOPs)",
        lambda c, w: ("", int(w["epochs"]) * episodes(c, "demos")),
        lambda c, w: 6.0 * int(w["epochs"]) * episodes(c, "demos") * 3 * int(w["hidden"]) ** 2,
    ),
    "rollout_policy": UnitRule(
        "held-out episode in the shard",
        lambda c, w: (
            "",
            episodes(c, "heldout") / int(policy_of(c)["rollout_shards"]),
        ),
    ),
    "policy_regression": UnitRule(
        "episode", lambda c, w: ("", episodes(c, "demos") + episodes(c, "heldout"))
    ),
    "aggregate_policy": UnitRule(
        "policy cell × bootstrap resample / 1000",
        lambda c, w: ("", policy_cells(c) * int(policy_of(c)["bootstrap"]) / 1000),
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
    "cost_knob_points": _const("job"),
}


def job_units(rule: str, config: Config, wildcards: Wildcards) -> tuple[str, float, float]:
    """(cost class, units, FLOPs) of one job of `rule` (FLOPs 0 for a rule without a model). A rule without a line in `UNITS`, or whose
    line cannot count this config, raises `MissingUnitsError` naming the rule."""
    if rule not in UNITS:
        raise MissingUnitsError(
            f"rule {rule!r} has no unit definition: add a line for it to "
            "tacgen_lib/estimate/units.py UNITS, then regenerate the calibration "
            "(python -m tacgen_lib.estimate.calibration)"
        )
    try:
        suffix, units = UNITS[rule].count(config, wildcards)
        flops = UNITS[rule].flops(config, wildcards) if UNITS[rule].flops else 0.0
    except (KeyError, TypeError, ValueError, ZeroDivisionError) as exc:
        raise MissingUnitsError(
            f"rule {rule!r}: cannot count its units ({UNITS[rule].unit}) for wildcards "
            f"{dict(wildcards)} from this config ({type(exc).__name__}: {exc}); fix its line in "
            "tacgen_lib/estimate/units.py UNITS"
        ) from exc
    name = UNITS[rule].same_as or rule
    return (f"{name}:{suffix}" if suffix else name), float(units), float(flops)
