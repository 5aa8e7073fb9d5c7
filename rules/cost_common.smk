"""Cost of accuracy (docs/cost.md): the knobs of config `cost.knobs`, each setting a module of this
workflow, and what each setting's points read; included by cost.smk.

`tacgen_lib.cost.knobs.KNOBS` is the one table of knobs. For a swept knob every setting (and
replicate) becomes a Snakemake module of this Snakefile with the knob's config keys set; the
module's copies of the main rules the knob reruns write under `results/cost/{knob}/{setting}/`
(`replace_prefix`), and read the main run's edges for everything else. Free knobs (the
backbone families, the generator's steps and samplers, the policy sweep) are the stages' own
grids and rerun nothing: a setting run is a cell of the grid (per seed), read from the stage's
summary. Both kinds go through rule cost_knob_points with a plan of setting runs.
"""

from tacgen_lib.align.cell_names import cell_name
from tacgen_lib.policy.policy_cells import all_cells as _policy_all_cells
from tacgen_lib.features.settings import backbones_pretrained
from tacgen_lib.cost.knobs import (
    KNOBS,
    knob_bootstrap,
    knob_metrics,
    knob_settings,
    moved_path,
    shared_runs,
)

TARGETS += ["results/report/cost_of_accuracy.html"]

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
    for c in pretraining_corpora(pretrain):
        if (c, pretrain["variant"]) not in preprocess:
            preprocess.append((c, pretrain["variant"]))
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


# ---- the free knobs: a setting run per cell of the stage's own grid (and per seed)


def _free_run(
    label, number, is_default, rep, benchmarks, options, edges=None, tables=None
):
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


def _steps_cells(sampler, steps):
    """generate_steps: the reference sampler at each of its steps."""
    return [
        (str(s), int(s), sampler, int(s))
        for s in sorted(int(x) for x in GENERATE["samplers"][sampler])
    ], str(steps)


def _sampler_cells(sampler, steps):
    """generate_sampler: each sampler at the reference steps (or its most)."""
    cells = []
    for i, (name, steps_list) in enumerate(GENERATE["samplers"].items()):
        st = steps if steps in [int(x) for x in steps_list] else max(steps_list)
        cells.append((f"{name} {int(st)}", i, name, int(st)))
    return cells, f"{sampler} {steps}"


_GENERATE_CELLS = {"generate_steps": _steps_cells, "generate_sampler": _sampler_cells}


def _generate_subject(knob):
    """The corpus, target and guidance a generator knob's points read (the run's reference
    guidance, generate_ref)."""
    entry = COST_KNOB_CONFIG.get(knob) or {}
    corpus = entry.get("corpus") or GENERATE_CORPORA[0]
    target = entry.get("target") or next(iter(GENERATE["corpora"][corpus]))
    return corpus, target, generate_ref()["guidance"]


def _generate_plan(knob):
    """Per cell (label, setting, sampler, steps) and generator seed: its sampling job. The
    default is the run's own reference cell (generate_ref)."""
    corpus, _, guidance = _generate_subject(knob)
    ref = generate_ref()
    cells, default = _GENERATE_CELLS[knob](ref["sampler"], ref["steps"])
    summary = {"summary": ["results/generate/summary.parquet"]}
    return [
        _free_run(
            label,
            setting,
            label == default,
            rep,
            [sample_benchmark(corpus, seed, sampler, guidance, steps)],
            {"sampler": sampler, "steps": steps},
            tables=summary,
        )
        for label, setting, sampler, steps in cells
        for rep, seed in enumerate(GENERATE["seeds"])
    ]


def _width_cells(s, v_cells):
    """policy_width: the V-only cells at the run's epochs."""
    widths = sorted({h for _, h, e, _ in v_cells if e == s.epochs})
    return [(str(h), h, h, s.epochs) for h in widths], str(s.hidden)


def _epochs_cells(s, v_cells):
    """policy_epochs: the V-only cells at the run's width."""
    epochs = sorted({e for _, h, e, _ in v_cells if h == s.hidden})
    return [(str(e), e, s.hidden, e) for e in epochs], str(s.epochs)


_POLICY_CELLS = {"policy_width": _width_cells, "policy_epochs": _epochs_cells}


def _policy_plan(knob):
    """Per cell (label, setting, hidden, epochs) and policy seed: its training job and its
    rollout shards. The default is the run's own width and epochs."""
    v_cells = [c for c in _policy_all_cells(POLICY_SETTINGS) if c[0] == "v"]
    cells, default = _POLICY_CELLS[knob](POLICY_SETTINGS, v_cells)
    summary = {"summary": [f"{POLICY_DIR}/summary.parquet"]}
    out = []
    for label, setting, h, e in cells:
        seeds = [c for c in v_cells if (c[1], c[2]) == (h, e)]
        for rep, c in enumerate(seeds):
            name = policy_cell_name(c)
            jobs = [f"results/benchmarks/train_policy/{name}.tsv"] + [
                f"results/benchmarks/rollout_policy/{name}/{k}.tsv"
                for k in range(POLICY_SETTINGS.rollout_shards)
            ]
            options = {"hidden": h, "epochs": e}
            out.append(
                _free_run(
                    label, setting, label == default, rep, jobs, options, tables=summary
                )
            )
    return out


def _backbone_plan(knob):
    """Per family of the run: every job that makes its backbones and the probe corpora's
    features (its own family_backbone jobs, or, for the main family, the main backbones and
    the main extraction of the probe corpora; the probes' cost, alike for every family, is
    left out). The default is the main DAG's family."""
    default = (MAIN_FAMILIES or [None])[0]
    summary = {"summary": ["results/backbones/summary.parquet"]}
    out = []
    for i, family in enumerate(FAMILIES.run):
        jobs = []
        for m in MODALITIES:
            if family in OWN_FAMILIES:
                jobs.append(f"results/benchmarks/family_backbone/{family}/{m}.tsv")
                continue
            jobs.append(f"results/benchmarks/pretrain_backbone/{m}.tsv")
            what = "vision" if m == "vision" else f"tactile~{FAMILY_VARIANT}"
            jobs += [
                f"results/benchmarks/extract_features/{c}/{what}.tsv"
                for c in FAMILY_CORPORA
            ]
        out.append(_free_run(family, i, family == default, 0, jobs, {}, edges=summary))
    return out


_FREE_PLANS = {
    "generate": _generate_plan,
    "policy": _policy_plan,
    "backbones": _backbone_plan,
}


def cost_setting_plan(knob):
    """Per setting run of a knob: label, x position, default flag, replicate, its edges by
    role (verified edges; a free knob's plain summary tables under `tables`), its benchmark
    files (a swept setting's own paths) and the reader's options.
    """
    if KNOBS[knob].free:
        return _FREE_PLANS[KNOBS[knob].reads](knob)
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
                "tables": {},
                "benchmarks": [moved_path(b, run.replace_prefix) for b in benchmarks],
                "options": {
                    "pretraining": backbones_pretrained(run.config["features"])
                },
            }
        )
    return plan


def cost_knob_options(knob):
    """What a knob's reader needs from the run's config (resamples, seed, metrics; a
    generator knob's corpus, target and guidance)."""
    probes = config["probes"]
    entry = COST_KNOB_CONFIG.get(knob) or {}
    options = {
        "bootstrap": knob_bootstrap(KNOBS[knob], entry, config),
        "seed": int(probes["seeds"][0]),
        "metrics": knob_metrics(KNOBS[knob], config),
    }
    if KNOBS[knob].reads == "generate":
        corpus, target, guidance = _generate_subject(knob)
        options |= {"corpus": corpus, "target": target, "guidance": guidance}
    return options


def cost_knob_inputs(wildcards):
    plan = cost_setting_plan(wildcards.knob)
    files = [
        p
        for run in plan
        for role in ("edges", "tables")
        for paths in run[role].values()
        for p in paths
    ]
    return {
        "edges": list(dict.fromkeys(files)),
        "benchmarks": list(dict.fromkeys(b for run in plan for b in run["benchmarks"])),
    }
