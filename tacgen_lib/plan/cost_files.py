"""What a cost knob's setting runs read: the main-run paths of a swept setting per reader (moved
by the setting's prefixes in `tacgen_lib.plan.cost`), and a free knob's setting runs, one per
cell of its stage's own grid (and per seed)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from tacgen_lib.align.cell_names import cell_name
from tacgen_lib.features.settings import pretraining_corpora
from tacgen_lib.plan.features import MODALITIES
from tacgen_lib.plan.generate import sample_benchmark
from tacgen_lib.plan.paths import benchmark_file, corpus_edge
from tacgen_lib.plan.policy import POLICY_DIR
from tacgen_lib.plan.stages import StagePlans
from tacgen_lib.policy.policy_cells import all_cells
from tacgen_lib.policy.policy_cells import cell_name as policy_cell_name

#: edges by role and benchmark files of one swept setting run
Files = tuple[dict[str, list[str]], list[str]]


def _heads_cells(corpus: str, heads: Mapping[str, Any], seeds: list[Any]) -> list[str]:
    """The alignment cells of the probes' heads (config probes.heads) at each seed."""
    return [
        cell_name(corpus, heads["variant"], s, heads["tau"], str(heads["n_train"])) for s in seeds
    ]


def align_files(stages: StagePlans, entry: Mapping[str, Any], run: Any, cost: Any) -> Files:
    """The align knob: each seed's heads cell's ranks and metrics, and its training job."""
    corpus = entry.get("corpus") or stages.align.corpora[0]
    seeds = entry.get("seeds") or stages.align.settings["seeds"]
    cells = _heads_cells(corpus, run.config["probes"]["heads"], seeds)
    return {
        "ranks": [f"results/align/{c}/ranks.parquet" for c in cells],
        "metrics": [f"results/align/{c}/metrics.parquet" for c in cells],
    }, [benchmark_file("train_heads", c) for c in cells]


def probe_files(stages: StagePlans, entry: Mapping[str, Any], run: Any, cost: Any) -> Files:
    """The probes' knobs: one family's raw-protocol job at the first probe seed."""
    family = entry.get("family", "force")
    job = f"{family}/protocol~raw/seed~{run.config['probes']['seeds'][0]}"
    return {"rows": [f"results/probes/{job}.parquet"]}, [benchmark_file("probe", job)]


def features_files(stages: StagePlans, entry: Mapping[str, Any], run: Any, cost: Any) -> Files:
    """The features knob: the pretrained-vs-random table and the jobs that make it."""
    feat = run.config["features"]
    corpus, variant = feat["pretrained_vs_random"]["corpus"], feat["pretrain"]["variant"]
    return {"table": ["results/features/pretrained_vs_random.parquet"]}, [
        *(benchmark_file("pretrain_backbone", m) for m in MODALITIES),
        benchmark_file("extract_features", f"{corpus}/vision"),
        benchmark_file("extract_features", f"{corpus}/tactile~{variant}"),
        "results/benchmarks/pretrained_vs_random.tsv",
    ]


def simulation_files(stages: StagePlans, entry: Mapping[str, Any], run: Any, cost: Any) -> Files:
    """Every job a simulation setting runs (the simulate job of the sweep corpus first): the
    corpora (the sweep corpus reduced), manifest and splits, backbones, the sweep corpus's
    preprocessing and features, its probes' heads and projections, its probe families."""
    cfg = run.config
    sim = (cost.get("sim_sweep") or {"corpus": "sim_paired"})["corpus"]
    corpora, pretrain = cfg["corpora"], cfg["features"]["pretrain"]
    families = [f for f, fam in sorted(cfg["probes"]["families"].items()) if fam["corpus"] == sim]
    cells = _heads_cells(sim, cfg["probes"]["heads"], cfg["align"]["seeds"])
    seed = cfg["probes"]["seeds"][0]
    preprocess = [(sim, v) for v in cfg["preprocess"]["variants"]]
    for c in pretraining_corpora(pretrain):
        if (c, pretrain["variant"]) not in preprocess:
            preprocess.append((c, pretrain["variant"]))
    sims = [sim] + [c for c in sorted(corpora) if c != sim and corpora[c]["kind"] == "simulated"]
    b = benchmark_file
    return {
        "samples": [corpus_edge(sim)],
        "rows": [f"results/probes/{f}/protocol~raw/seed~{seed}.parquet" for f in families],
    }, [
        *(b("simulate_corpus", f"{c}/{k}") for c in sims for k in range(corpora[c]["shards"])),
        *(b("merge_corpus", c) for c in sims),
        *(b("ingest_tvl", c) for c in sorted(corpora) if c not in sims),
        "results/benchmarks/fuse_manifest.tsv",
        "results/benchmarks/make_splits.tsv",
        *(b("background_subtract", f"{c}/{v}") for c, v in preprocess),
        *(b("pretrain_backbone", m) for m in MODALITIES),
        b("extract_features", f"{sim}/vision"),
        *(b("extract_features", f"{sim}/tactile~{v}") for v in cfg["preprocess"]["variants"]),
        *(b("train_heads", c) for c in cells),
        *(b("project_aligned", f"{c}/{sim}") for c in cells),
        *(b("probe", f"{f}/protocol~raw/seed~{seed}") for f in families),
    ]


#: a swept knob's reader -> the files of one of its setting runs
SETTING_FILES: dict[str, Callable[..., Files]] = {
    "align": align_files,
    "probe_bootstrap": probe_files,
    "probe_permutations": probe_files,
    "features": features_files,
    "simulation": simulation_files,
}


def free_run(
    label: str,
    number: float,
    is_default: bool,
    rep: int,
    benchmarks: list[str],
    options: dict[str, Any],
    edges: dict[str, list[str]] | None = None,
    tables: dict[str, list[str]] | None = None,
) -> dict[str, Any]:
    """One setting run of a free knob, in the form `CostPlan.setting_plan` gives every run."""
    return {
        "label": label,
        "number": float(number),
        "is_default": is_default,
        "rep": rep,
        "edges": edges or {},
        "tables": tables or {},
        "benchmarks": benchmarks,
        "options": options,
    }


def generate_subject(
    stages: StagePlans, knob: str, knob_config: Mapping[str, Any]
) -> tuple[str, str, str]:
    """The corpus, target and guidance a generator knob's points read (the run's reference
    guidance)."""
    entry = knob_config.get(knob) or {}
    corpus = entry.get("corpus") or stages.generate.corpora[0]
    target = entry.get("target") or next(iter(stages.generate.settings["corpora"][corpus]))
    return corpus, target, stages.generate.reference()["guidance"]


def _generate_cells(
    samplers: Mapping[str, list[Any]], knob: str, sampler: str, steps: int
) -> tuple[list[tuple[str, int, str, int]], str]:
    """A generator knob's cells (label, setting, sampler, steps) and its default's label:
    generate_steps, the reference sampler at each of its steps; generate_sampler, each
    sampler at the reference steps (or its most)."""
    if knob == "generate_steps":
        cells = [(str(s), s, sampler, s) for s in sorted(int(x) for x in samplers[sampler])]
        return cells, str(steps)
    cells = []
    for i, (name, steps_list) in enumerate(samplers.items()):
        st = steps if steps in [int(x) for x in steps_list] else max(steps_list)
        cells.append((f"{name} {int(st)}", i, name, int(st)))
    return cells, f"{sampler} {steps}"


def generate_plan(stages: StagePlans, knob: str, knob_config: Mapping[str, Any]) -> list[dict]:
    """Per cell and generator seed: its sampling job. The default is the run's own reference
    cell."""
    corpus, _, guidance = generate_subject(stages, knob, knob_config)
    ref, settings = stages.generate.reference(), stages.generate.settings
    cells, default = _generate_cells(settings["samplers"], knob, ref["sampler"], ref["steps"])
    summary = {"summary": ["results/generate/summary.parquet"]}
    return [
        free_run(
            label,
            setting,
            label == default,
            rep,
            [sample_benchmark(corpus, seed, sampler, guidance, steps)],
            {"sampler": sampler, "steps": steps},
            tables=summary,
        )
        for label, setting, sampler, steps in cells
        for rep, seed in enumerate(settings["seeds"])
    ]


def _policy_cells(s: Any, v_cells: list[tuple], knob: str) -> tuple[list[tuple], str]:
    """A policy knob's cells (label, setting, hidden, epochs) and its default's label:
    policy_width, the V-only cells at the run's epochs; policy_epochs, at the run's width."""
    if knob == "policy_width":
        widths = sorted({h for _, h, e, _ in v_cells if e == s.epochs})
        return [(str(h), h, h, s.epochs) for h in widths], str(s.hidden)
    epochs = sorted({e for _, h, e, _ in v_cells if h == s.hidden})
    return [(str(e), e, s.hidden, e) for e in epochs], str(s.epochs)


def policy_plan(stages: StagePlans, knob: str, knob_config: Mapping[str, Any]) -> list[dict]:
    """Per cell and policy seed: its training job and its rollout shards. The default is the
    run's own width and epochs."""
    s = stages.policy.settings
    v_cells = [c for c in all_cells(s) if c[0] == "v"]
    cells, default = _policy_cells(s, v_cells, knob)
    summary = {"summary": [f"{POLICY_DIR}/summary.parquet"]}
    out = []
    for label, setting, h, e in cells:
        seeds = [c for c in v_cells if (c[1], c[2]) == (h, e)]
        for rep, c in enumerate(seeds):
            name = policy_cell_name(c)
            jobs = [benchmark_file("train_policy", name)] + [
                benchmark_file("rollout_policy", f"{name}/{k}") for k in range(s.rollout_shards)
            ]
            options = {"hidden": h, "epochs": e}
            out.append(
                free_run(label, setting, label == default, rep, jobs, options, tables=summary)
            )
    return out


def backbone_plan(stages: StagePlans, knob: str, knob_config: Mapping[str, Any]) -> list[dict]:
    """Per family of the run: every job that makes its backbones and the probe corpora's
    features (its own family_backbone jobs, or, for the main family, the main backbones and the
    main extraction of the probe corpora; the probes' cost, alike for every family, is left
    out). The default is the main DAG's family."""
    families = stages.families
    default = (families.main or [None])[0]
    summary = {"summary": ["results/backbones/summary.parquet"]}
    out = []
    for i, family in enumerate(families.settings.run):
        jobs = []
        for m in MODALITIES:
            if family in families.own:
                jobs.append(benchmark_file("family_backbone", f"{family}/{m}"))
                continue
            jobs.append(benchmark_file("pretrain_backbone", m))
            what = "vision" if m == "vision" else f"tactile~{families.variant}"
            jobs += [benchmark_file("extract_features", f"{c}/{what}") for c in families.corpora]
        out.append(free_run(family, i, family == default, 0, jobs, {}, edges=summary))
    return out


#: a free knob's stage -> its setting runs
FREE_PLANS: dict[str, Callable[..., list[dict]]] = {
    "generate": generate_plan,
    "policy": policy_plan,
    "backbones": backbone_plan,
}
