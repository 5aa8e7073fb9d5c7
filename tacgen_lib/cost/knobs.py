"""The cost knobs: the one table that describes each knob (docs/cost.md).

A swept knob is the main workflow run again with config keys changed. Each setting of a knob
(and each replicate of a setting, where the knob measures a Monte Carlo error) becomes a
Snakemake `module` of the stages' rules (rules/stages.smk; rules/cost_common.smk includes the
statements `tacgen_lib.plan.cost.CostPlan.modules_source` writes): its config is the run's
merged config with the knob's keys set, and `replace_prefix` moves the outputs of the main
rules it runs again (`Knob.reruns`) from the folders in `Knob.moves` to
`results/cost/{knob}/{setting}/`. Every other input (splits, backbones, features the knob does
not touch) is the main run's own edge. No rule is written twice: a setting's jobs are the main
rules' jobs, so a knob at its default setting reproduces the main run's edge bit for bit (a
test checks this), the run-time estimate prices them with the main rules' calibration, and a
change to a main rule reaches the sweep by itself.

What a knob's points read (`Knob.reads`) names one reader of `tacgen_lib.cost.readers`. The
backbone, generator and policy knobs are `free`: their settings are the stages' own grids
(their `keys`: `backbones.run`, `generate.samplers`, `policy.sweep_*`), so they rerun nothing;
their points come through the same rule and the same readers as a swept knob's.

    knob              config key(s) a setting sets              reruns (main rules)
    align_steps       align.steps (align.budget = steps)        train_heads
    align_n           align.n_train, probes.heads.n_train       train_heads
    probe_bootstrap   probes.bootstrap (× replicate seeds)      probe
    probe_permutations probes.permutations (× replicate seeds)  probe
    presses           corpora.<sweep corpus>.presses            corpus → probes of that corpus
    tactile_resolution corpora.<sweep corpus>.tactile_size      corpus → probes of that corpus
    image_size        features.image_size                       backbones, features, check
    backbone_arch     features.backbones.tactile.arch           backbones, features, check
    pretrain_epochs   features.pretrain.epochs                  backbones, features, check
    backbones         (free) backbones.run                      none: the families' own jobs
    generate_steps    (free) generate.samplers (steps)          none: the sampling jobs
    generate_sampler  (free) generate.samplers (samplers)       none: the sampling jobs
    policy_width      (free) policy.sweep_hidden                none: the V-only policy jobs
    policy_epochs     (free) policy.sweep_epochs                none: the V-only policy jobs
"""

from __future__ import annotations

import copy
import dataclasses
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from tacgen_lib.features.archs import ARCHS
from tacgen_lib.features.settings import pretraining_corpora
from tacgen_lib.generate.regime_sets import regime_corpora

__all__ = [
    "KNOBS",
    "Knob",
    "Setting",
    "UnknownKnobError",
    "knob_bootstrap",
    "knob_metrics",
    "knob_settings",
    "moved_path",
    "setting_label",
    "shared_runs",
]

#: the main rules a simulation setting runs again: the corpora (the sweep corpus reduced)
#: through backbones, features and heads to the sweep corpus's probes. Snakemake moves rule
#: path patterns, so whole stage folders move: the setting is the pipeline again up to its
#: probes, never a mix of its corpus and the main run's.
_SIM_RERUNS = (
    "simulate_corpus",
    "merge_corpus",
    "ingest_tvl",
    "fuse_manifest",
    "make_splits",
    "background_subtract",
    "pretrain_backbone",
    "extract_vision_features",
    "extract_tactile_features",
    "train_heads",
    "project_aligned",
    "probe",
)
_SIM_MOVES = (
    "results/corpus/",
    "results/preprocess/",
    "results/features/",
    "results/align/",
    "results/probes/",
)
_FEATURES_RERUNS = (
    "pretrain_backbone",
    "extract_vision_features",
    "extract_tactile_features",
    "pretrained_vs_random",
)


@dataclass(frozen=True)
class Knob:
    """One knob of the cost page.

    stage: the stage whose accuracy it trades (corpus | features | align | probes | generate |
    policy). keys: dotted config paths a setting sets to its value ("{sim}" is the
    simulation sweep's corpus; a trailing "[]" sets a one-element list). fixed: further keys
    every setting sets (a value "{sim_n}" is `cost.sim_sweep.n`). reruns: the main rules run
    again per setting; moves: the result folders their outputs move from (prefixes of the
    rules' path patterns, as Snakemake's `replace_prefix` matches them).
    replicate_key: a config key each replicate seed sets (the knob measures a Monte Carlo
    error; replicate r sets it to the run's first probe seed + r, so replicate 0 is the
    main run's draw). reads: the reader of `tacgen_lib.cost.readers` that turns a setting's
    edges into metrics; metrics: the metric names the page shows (None: all the reader gives;
    "{vision_target}" / "{tactile_target}" are the pretrained-vs-random targets). axis: how a
    value becomes the x position ("value", "height" of an [H, W] frame, "width" of a ViT).
    free: the settings are a stage's own grid, the config key(s) `keys` name (no rerun, no
    module; the grid's cells and seeds are the setting runs). has_default: whether a
    value can be the run's own setting (not for `align_steps`: the run budgets epochs).
    bootstrap_key: the config key of the resamples of the points' CIs (else the knob's
    `bootstrap`, default 2000).
    """

    name: str
    stage: str
    reads: str
    keys: tuple[str, ...] = ()
    fixed: Mapping[str, Any] = field(default_factory=dict)
    reruns: tuple[str, ...] = ()
    moves: tuple[str, ...] = ()
    replicate_key: str | None = None
    metrics: tuple[str, ...] | None = None
    axis: str = "value"
    free: bool = False
    has_default: bool = True
    bootstrap_key: str | None = None


# fmt: off
# (a table: one knob per entry, its keys, reruns and moves side by side; the formatter would put
# every argument on a line of its own)
_SIM = dict(reruns=_SIM_RERUNS, moves=_SIM_MOVES, bootstrap_key="probes.bootstrap",
            fixed={"corpora.{sim}.n": "{sim_n}", "corpora.{sim}.shards": 1})
_FEATURES = dict(reruns=_FEATURES_RERUNS, moves=("results/features/",),
                 bootstrap_key="features.pretrained_vs_random.bootstrap")
_ACCURACY = ("vision {vision_target} accuracy", "tactile {tactile_target} accuracy")
KNOBS: dict[str, Knob] = {k.name: k for k in (
    Knob("align_steps", stage="align", reads="align", keys=("align.steps",),
         fixed={"align.budget": "steps"}, reruns=("train_heads",), moves=("results/align/",),
         has_default=False),
    Knob("align_n", stage="align", reads="align",
         keys=("probes.heads.n_train", "align.n_train[]"), reruns=("train_heads",),
         moves=("results/align/",)),
    Knob("probe_bootstrap", stage="probes", reads="probe_bootstrap", keys=("probes.bootstrap",),
         reruns=("probe",), moves=("results/probes/",), replicate_key="probes.resample_seed"),
    Knob("probe_permutations", stage="probes", reads="probe_permutations",
         keys=("probes.permutations",), reruns=("probe",), moves=("results/probes/",),
         replicate_key="probes.resample_seed"),
    Knob("presses", stage="corpus", reads="simulation", keys=("corpora.{sim}.presses",),
         metrics=("force band p05–p95 width (N)", "force_p50 ΔR² V+T − V"), **_SIM),
    Knob("tactile_resolution", stage="corpus", reads="simulation",
         keys=("corpora.{sim}.tactile_size",), axis="height",
         metrics=("force_p50 ΔR² V+T − V", "hardness Δaccuracy V+T − V",
                  "frames/s (simulate job, one core)"), **_SIM),
    Knob("image_size", stage="features", reads="features", keys=("features.image_size",),
         metrics=_ACCURACY, **_FEATURES),
    # the tactile ViT's width (the vision side is a SimCLR ResNet, whose width is its arch's)
    Knob("backbone_arch", stage="features", reads="features", axis="width",
         keys=("features.backbones.tactile.arch",),
         metrics=_ACCURACY, **_FEATURES),
    Knob("pretrain_epochs", stage="features", reads="features",
         keys=("features.pretrain.epochs",),
         metrics=("vision {vision_target} Δaccuracy pretrained − random",
                  "tactile {tactile_target} Δaccuracy pretrained − random"), **_FEATURES),
    Knob("backbones", stage="features", reads="backbones", keys=("backbones.run",), free=True),
    Knob("generate_steps", stage="generate", reads="generate", keys=("generate.samplers",),
         free=True),
    Knob("generate_sampler", stage="generate", reads="generate", keys=("generate.samplers",),
         free=True),
    Knob("policy_width", stage="policy", reads="policy", keys=("policy.sweep_hidden",),
         free=True),
    Knob("policy_epochs", stage="policy", reads="policy", keys=("policy.sweep_epochs",),
         free=True),
)}
# fmt: on


class UnknownKnobError(ValueError):
    """config cost.knobs names a knob `KNOBS` does not have."""


@dataclass(frozen=True)
class Setting:
    """One run of a swept knob: `label` (the value as paths and the page write it), `number`
    (its x position; NaN where only the reader knows it, e.g. "all" rows), `is_default` (the
    run's own value), `rep` (replicate index, 0 without replicates), `module` (the Snakemake
    module's name, also the prefix of its rules' names), `root` (its results folder),
    `config` (the module's config) and `replace_prefix` (Snakemake's: main path prefix ->
    moved prefix)."""

    knob: str
    label: str
    number: float
    is_default: bool
    rep: int
    module: str
    root: str
    config: dict[str, Any]
    replace_prefix: dict[str, str]


def setting_label(value: Any) -> str:
    """A knob value as paths and the page write it: 300 -> "300", [120, 160] -> "120x160"."""
    if isinstance(value, list | tuple):
        return "x".join(str(int(v)) for v in value)
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)


def _number(knob: Knob, value: Any) -> float:
    if knob.axis == "height":
        return float(value[0])
    if knob.axis == "width":
        return float(ARCHS[str(value)].embed_dim)
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def _context(config: Mapping[str, Any]) -> dict[str, Any]:
    cost = config.get("cost") or {}
    sim = cost.get("sim_sweep") or {"corpus": "sim_paired", "n": 400}
    targets = config["features"]["pretrained_vs_random"]["targets"]
    return {
        "sim": sim["corpus"],
        "sim_n": int(sim["n"]),
        "vision_target": targets["vision"],
        "tactile_target": targets["tactile"],
    }


def _path(key: str, ctx: Mapping[str, Any]) -> tuple[list[str], bool]:
    as_list = key.endswith("[]")
    return key.removesuffix("[]").format(**ctx).split("."), as_list


def _get(config: Mapping[str, Any], parts: Sequence[str]) -> Any:
    node: Any = config
    for p in parts:
        node = node[p]
    return node


def _set(config: dict[str, Any], parts: Sequence[str], value: Any) -> None:
    node = config
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = value


def _fill(value: Any, ctx: Mapping[str, Any]) -> Any:
    if isinstance(value, str) and value.startswith("{") and value.endswith("}"):
        return ctx[value[1:-1]]
    return value


def knob_bootstrap(knob: Knob, entry: Mapping[str, Any], config: Mapping[str, Any]) -> int:
    """Resamples of a knob's point CIs: the knob's `bootstrap`, else its `bootstrap_key`'s
    value in the run's config, else 2000."""
    if entry.get("bootstrap"):
        return int(entry["bootstrap"])
    if knob.bootstrap_key:
        return int(_get(config, knob.bootstrap_key.split(".")))
    return 2000


def knob_metrics(knob: Knob, config: Mapping[str, Any]) -> list[str] | None:
    """The metric names a knob's page shows, with the config's targets filled in."""
    if knob.metrics is None:
        return None
    ctx = _context(config)
    return [m.format(**ctx) for m in knob.metrics]


def _same(a: Any, b: Any) -> bool:
    return setting_label(a) == setting_label(b)


def _without_regime(cfg: dict[str, Any], sweep_corpus: str) -> None:
    """A simulation setting simulates every corpus of its manifest again; the regime's
    natural corpora feed none of the sweep corpus's probes, so the setting drops them (no
    rho left in the regime) instead of simulating them once per setting. Its backbones, which
    it pretrains again, learn from the pretraining corpora it keeps, or from the sweep corpus
    where it keeps none (the default's V pretrains on the natural corpora alone)."""
    regime = cfg.get("regime") or {}
    dropped = set(regime_corpora(regime))
    for corpus in dropped:
        cfg["corpora"].pop(corpus, None)
    if regime:
        cfg["regime"] = {**regime, "rhos": []}
    pretrain = cfg["features"]["pretrain"]
    kept = [c for c in pretraining_corpora(pretrain) if c not in dropped]
    pretrain["corpus"] = kept or [sweep_corpus]


def knob_settings(name: str, entry: Mapping[str, Any], config: Mapping[str, Any]) -> list[Setting]:
    """Every run a swept knob needs: one per value (× replicate), each with the module config
    (`config` with the knob's keys set, no knobs of its own, `cost.setting` naming it) and the
    prefixes its outputs move by. `entry` is the knob's config (`values`, `replicates`...).

    Raises UnknownKnobError for a name `KNOBS` lacks, ValueError for a free knob given values
    or a swept knob without any.
    """
    if name not in KNOBS:
        raise UnknownKnobError(
            f"config cost.knobs: {name!r} is not a knob of this workflow (known: {sorted(KNOBS)})"
        )
    knob = KNOBS[name]
    values = list(entry.get("values") or [])
    if knob.free:
        if values:
            raise ValueError(
                f"config cost.knobs.{name}: its settings are the stage's own grid "
                f"({', '.join(knob.keys)}); widen that instead"
            )
        return []
    if not values:
        raise ValueError(f"config cost.knobs.{name}: no values to sweep")
    ctx = _context(config)
    paths = [_path(k, ctx) for k in knob.keys]
    # the run's own setting: every scalar key at its value (a list key is a grid)
    defaults = [_get(config, parts) for parts, as_list in paths if not as_list]
    reps = int(entry.get("replicates", 5)) if knob.replicate_key else 1
    first_seed = int(config["probes"]["seeds"][0])
    out = []
    for value in values:
        label = setting_label(value)
        for rep in range(reps):
            tag = f"{label}/rep~{rep}" if knob.replicate_key else label
            root = f"results/cost/{name}/{tag}/"
            module = re.sub(r"[^A-Za-z0-9_]", "_", f"cost_{name}_{tag}")
            cfg = copy.deepcopy(dict(config))
            for parts, as_list in paths:
                _set(cfg, parts, [value] if as_list else value)
            for key, fixed in knob.fixed.items():
                _set(cfg, _path(key, ctx)[0], _fill(fixed, ctx))
            if knob.replicate_key:
                _set(cfg, knob.replicate_key.split("."), first_seed + rep)
            if knob.reads == "simulation":
                _without_regime(cfg, ctx["sim"])
            cfg["cost"] = {
                "knobs": {},
                "grid_knobs": False,
                "setting": {"knob": name, "label": label, "rep": rep, "module": module},
            }
            moves = {
                m.format(**ctx): root + m.format(**ctx).removeprefix("results/") for m in knob.moves
            }
            moves |= {"results/benchmarks/": root + "benchmarks/", "results/logs/": root + "logs/"}
            is_default = knob.has_default and all(_same(value, d) for d in defaults)
            out.append(
                Setting(
                    name, label, _number(knob, value), is_default, rep, module, root, cfg, moves
                )
            )
    return out


def shared_runs(runs: Sequence[Setting]) -> list[Setting]:
    """`runs` (of every swept knob, in order) with settings whose configs are the same run
    (e.g. each knob's own default setting, or a default shared by two simulation knobs) and
    the same moved folders made one: a later one keeps its knob, label and flags but takes the first one's module, folder
    and prefixes, so the run happens once and both knobs read it."""
    first: dict[str, Setting] = {}
    out = []
    for run in runs:
        cfg = {
            **run.config,
            "cost": {k: v for k, v in run.config["cost"].items() if k != "setting"},
        }
        # the same config and the same folders moved (else a rule could write a main path)
        key = json.dumps([cfg, sorted(run.replace_prefix)], sort_keys=True)
        owner = first.setdefault(key, run)
        out.append(
            run
            if owner is run
            else dataclasses.replace(
                run,
                module=owner.module,
                root=owner.root,
                config=owner.config,
                replace_prefix=owner.replace_prefix,
            )
        )
    return out


def moved_path(path: str, replace_prefix: Mapping[str, str]) -> str:
    """Where a main-workflow path lands in a setting's module: Snakemake's `replace_prefix`
    (one matching prefix replaced; none: the path is the main run's own)."""
    hits = [p for p in replace_prefix if path.startswith(p)]
    if len(hits) > 1:
        raise ValueError(f"{path}: prefixes {hits} all match (ambiguous replace_prefix)")
    return replace_prefix[hits[0]] + path[len(hits[0]) :] if hits else path
