"""Cost of accuracy (docs/cost.md): the knobs of config `cost.knobs`, each setting a module of this
workflow, and what each setting's points read; included by cost.smk.

`tacgen_lib.cost.knobs.KNOBS` is the one table of knobs. For a swept knob every setting (and
replicate) becomes a Snakemake module of this Snakefile with the knob's config keys set; the
module's copies of the main rules the knob reruns write under `results/cost/{knob}/{setting}/`
(`replace_prefix`), and read the main run's edges for everything else. Free knobs (the
generator's steps and samplers, the policy sweep) are the stages' own grids and rerun nothing.
"""

from tacgen_lib.align.cells import cell_name
from tacgen_lib.features.settings import backbones_pretrained
from tacgen_lib.cost.knobs import (
    KNOBS,
    knob_bootstrap,
    knob_metrics,
    knob_settings,
    moved_path,
    shared_runs,
)

COST = config.get("cost") or {}
COST_KNOB_CONFIG = COST.get("knobs") or {}
COST_POINTS = "results/cost/points/{knob}.parquet"
#: knob -> its settings' runs (empty for a free knob); an unknown name stops here. A setting
#: that is the same run as another knob's (each knob's own default) runs once.
_RUNS = shared_runs(
    [
        run
        for name, entry in COST_KNOB_CONFIG.items()
        for run in knob_settings(name, entry or {}, config)
    ]
)
COST_SETTINGS = {
    name: [r for r in _RUNS if r.knob == name] for name in COST_KNOB_CONFIG
}
SWEPT_KNOBS = [k for k, runs in COST_SETTINGS.items() if runs]
# the backbone-family knob compares the families the run makes: more than one
_STAGE_RUNS = {
    "generate": bool(GENERATE_CORPORA),
    "policy": POLICY_ON,
    "features": len(FAMILIES.run) > 1 and bool(FAMILIES.probes),
}
FREE_KNOBS = [
    k
    for k, knob in KNOBS.items()
    if knob.free
    and _STAGE_RUNS[knob.stage]
    and (k in COST_KNOB_CONFIG or COST.get("grid_knobs", True))
]

# One module per setting: this Snakefile with the setting's config, its rerun rules renamed
# `<module>_<rule>`. (`use rule` takes its rule list literally; the list comes from KNOBS, so
# the statement's own call is made here.)
_MODULES = {}
for _run in _RUNS:
    _MODULES.setdefault(_run.module, (_run, set()))[1].update(KNOBS[_run.knob].reruns)
for _module, (_run, _rules) in _MODULES.items():
    workflow.module(
        _module,
        snakefile=str(WORKFLOW_ROOT / "Snakefile"),
        config=_run.config,
        replace_prefix=_run.replace_prefix,
    )
    workflow.userule(
        rules=sorted(_rules), from_module=_module, name_modifier=f"{_module}_*"
    )(None)


def cost_knobs():
    """The knobs the page shows: the swept ones, then the free ones."""
    return SWEPT_KNOBS + [k for k in FREE_KNOBS if k not in SWEPT_KNOBS]


def cost_points(wildcards=None):
    return [COST_POINTS.format(knob=k) for k in cost_knobs()]


# ---- the main-run paths a setting's points read, per reader (moved by the setting's prefixes)


def _align_files(knob, run):
    entry, heads = COST_KNOB_CONFIG[knob], run.config["probes"]["heads"]
    corpus = entry.get("corpus") or ALIGN_CORPORA[0]
    cells = [
        cell_name(corpus, heads["variant"], s, heads["tau"], str(heads["n_train"]))
        for s in entry.get("seeds") or ALIGN["seeds"]
    ]
    return {
        "ranks": [f"results/align/{c}/ranks.parquet" for c in cells],
        "metrics": [f"results/align/{c}/metrics.parquet" for c in cells],
    }, [f"results/benchmarks/train_heads/{c}.tsv" for c in cells]


def _probe_files(knob, run):
    family = COST_KNOB_CONFIG[knob].get("family", "force")
    job = f"{family}/protocol~raw/seed~{run.config['probes']['seeds'][0]}"
    return {"rows": [f"results/probes/{job}.parquet"]}, [
        f"results/benchmarks/probe/{job}.tsv"
    ]


def _features_files(knob, run):
    feat = run.config["features"]
    corpus, variant = (
        feat["pretrained_vs_random"]["corpus"],
        feat["pretrain"]["variant"],
    )
    return {"table": ["results/features/pretrained_vs_random.parquet"]}, [
        *(f"results/benchmarks/pretrain_backbone/{m}.tsv" for m in MODALITIES),
        f"results/benchmarks/extract_features/{corpus}/vision.tsv",
        f"results/benchmarks/extract_features/{corpus}/tactile~{variant}.tsv",
        "results/benchmarks/pretrained_vs_random.tsv",
    ]


def _simulation_files(knob, run):
    """Every job a simulation setting runs (the simulate job of the sweep corpus first): the
    corpora (the sweep corpus reduced), manifest and splits, backbones, the sweep corpus's
    preprocessing and features, its probes' heads and projections, its probe families.
    """
    cfg, sim = run.config, (COST.get("sim_sweep") or {"corpus": "sim_paired"})["corpus"]
    corpora, heads = cfg["corpora"], cfg["probes"]["heads"]
    pretrain = cfg["features"]["pretrain"]
    families = [
        f
        for f, fam in sorted(cfg["probes"]["families"].items())
        if fam["corpus"] == sim
    ]
    cells = [
        cell_name(sim, heads["variant"], s, heads["tau"], str(heads["n_train"]))
        for s in cfg["align"]["seeds"]
    ]
    seed, b = cfg["probes"]["seeds"][0], "results/benchmarks"
    preprocess = [(sim, v) for v in cfg["preprocess"]["variants"]]
    if (pretrain["corpus"], pretrain["variant"]) not in preprocess:
        preprocess.append((pretrain["corpus"], pretrain["variant"]))
    sims = [sim] + [
        c for c in sorted(corpora) if c != sim and corpora[c]["kind"] == "simulated"
    ]
    return {
        "samples": [corpus_edge(sim)],
        "rows": [
            f"results/probes/{f}/protocol~raw/seed~{seed}.parquet" for f in families
        ],
    }, [
        *(
            f"{b}/simulate_corpus/{c}/{k}.tsv"
            for c in sims
            for k in range(corpora[c]["shards"])
        ),
        *(f"{b}/merge_corpus/{c}.tsv" for c in sims),
        *(f"{b}/ingest_tvl/{c}.tsv" for c in sorted(corpora) if c not in sims),
        f"{b}/fuse_manifest.tsv",
        f"{b}/make_splits.tsv",
        *(f"{b}/background_subtract/{c}/{v}.tsv" for c, v in preprocess),
        *(f"{b}/pretrain_backbone/{m}.tsv" for m in MODALITIES),
        f"{b}/extract_features/{sim}/vision.tsv",
        *(
            f"{b}/extract_features/{sim}/tactile~{v}.tsv"
            for v in cfg["preprocess"]["variants"]
        ),
        *(f"{b}/train_heads/{c}.tsv" for c in cells),
        *(f"{b}/project_aligned/{c}/{sim}.tsv" for c in cells),
        *(f"{b}/probe/{f}/protocol~raw/seed~{seed}.tsv" for f in families),
    ]


_SETTING_FILES = {
    "align": _align_files,
    "probe_bootstrap": _probe_files,
    "probe_permutations": _probe_files,
    "features": _features_files,
    "simulation": _simulation_files,
}


def cost_setting_plan(knob):
    """Per setting run of a swept knob: label, x position, default flag, replicate, its edges
    by role and its benchmark files (the setting's own paths) and the reader's options.
    """
    plan = []
    for run in COST_SETTINGS[knob]:
        edges, benchmarks = _SETTING_FILES[KNOBS[knob].reads](knob, run)
        plan.append(
            {
                "label": run.label,
                "number": run.number,
                "is_default": run.is_default,
                "rep": run.rep,
                "edges": {
                    role: [moved_path(p, run.replace_prefix) for p in paths]
                    for role, paths in edges.items()
                },
                "benchmarks": [moved_path(b, run.replace_prefix) for b in benchmarks],
                "options": {
                    "pretraining": backbones_pretrained(run.config["features"])
                },
            }
        )
    return plan


def cost_knob_options(knob):
    """What a knob's reader needs from the run's config (resamples, seed, metrics)."""
    probes = config["probes"]
    return {
        "bootstrap": knob_bootstrap(KNOBS[knob], COST_KNOB_CONFIG[knob], config),
        "seed": int(probes["seeds"][0]),
        "metrics": knob_metrics(KNOBS[knob], config),
    }


def cost_knob_inputs(wildcards):
    plan = cost_setting_plan(wildcards.knob)
    return {
        "edges": [p for run in plan for paths in run["edges"].values() for p in paths],
        "benchmarks": [b for run in plan for b in run["benchmarks"]],
    }
