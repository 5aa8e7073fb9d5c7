"""Cost of accuracy, simulation and features knobs (issue 14): one setting at a time around the
config, each setting's seconds from its jobs' benchmark files, its accuracy with a CI.

Knobs (config/cost.yaml, `cost.knobs.<knob>.values`):
  presses, tactile_resolution   a reduced copy of `cost.sim_sweep.corpus` (its first
                                `cost.sim_sweep.n` samples, same sample_ids and splits) is
                                re-simulated per setting and probed as the probes stage does
  image_size, backbone_arch,    a backbone per setting (pretrained, or the seeded random init at
  pretrain_epochs               epochs 0), features and the pretrained-vs-random check
Each knob writes results/cost/points/{knob}.parquet (tacgen_lib.cost.points.POINT_COLUMNS).
Rules reuse the stage scripts (simulate_corpus, merge_corpus, background_subtract,
extract_features, pretrain_backbone, pretrained_vs_random) with the setting in the path.
"""

from tacgen_lib.cost.knob_metrics import knob_metric_ids
from tacgen_lib.features.vit import ARCHS

COST = config.get("cost") or {}
COST_KNOBS = COST.get("knobs") or {}
SIM_KNOBS = [k for k in ("presses", "tactile_resolution") if k in COST_KNOBS]
FEATURE_KNOBS = [
    k for k in ("image_size", "backbone_arch", "pretrain_epochs") if k in COST_KNOBS
]
SIM_SWEEP = COST.get("sim_sweep") or {"corpus": "sim_paired", "n": 400}
SIM_BASE = SIM_SWEEP["corpus"]
SIM_DIR = "results/cost/sim/presses~{presses}/tactile~{tactile}"
FEAT_DIR = "results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}"
PVR = config["features"]["pretrained_vs_random"]
PROBE_VARIANT = config["probes"]["heads"]["variant"]
if SIM_KNOBS and (
    SIM_BASE not in SIM_CORPORA or int(SIM_SWEEP["n"]) > int(CORPORA[SIM_BASE]["n"])
):
    raise ValueError(
        f"config cost.sim_sweep: corpus {SIM_BASE!r} must be a simulated corpus of the config "
        f"with n >= {SIM_SWEEP['n']} (its sample_ids and splits are reused)"
    )


def _hw(value):
    """A tactile resolution as the path writes it: [120, 160] -> '120x160'."""
    h, w = (int(v) for v in value)
    return f"{h}x{w}"


def sim_default():
    c = CORPORA.get(SIM_BASE, {})
    return {
        "presses": int(c.get("presses", 8)),
        "tactile": _hw(c.get("tactile_size", [120, 160])),
    }


def features_default():
    b = FEAT["backbones"]
    return {
        "size": int(FEAT["image_size"]),
        "arch": b["vision"]["arch"],
        "epochs": int(PRETRAIN["epochs"]),
    }


def knob_settings(knob):
    """(label, number for the log axis, is_default, path wildcards) of each setting."""
    out = []
    for value in COST_KNOBS[knob]["values"]:
        if knob in ("presses", "tactile_resolution"):
            w = sim_default()
            if knob == "presses":
                w["presses"], label, num = int(value), str(int(value)), int(value)
            else:
                w["tactile"] = label = _hw(value)
                num = int(value[0])
            is_default = w == sim_default()
        else:
            w = features_default()
            if knob == "image_size":
                w["size"], label, num = int(value), str(int(value)), int(value)
            elif knob == "backbone_arch":
                w["arch"], label = str(value), str(value)
                num = ARCHS[str(value)].embed_dim
            else:
                w["epochs"], label, num = int(value), str(int(value)), int(value)
            is_default = w == features_default() and (
                FEAT["backbones"]["tactile"]["arch"] == w["arch"]
            )
        out.append((label, num, is_default, w))
    return out


def sim_setting_jobs(w):
    """The benchmark files of one simulation setting's jobs (what its seconds sum)."""
    d = f"presses~{w['presses']}/tactile~{w['tactile']}"
    return [
        f"results/benchmarks/cost_simulate_corpus/{d}/0.tsv",
        f"results/benchmarks/cost_merge_corpus/{d}.tsv",
        f"results/benchmarks/cost_background_subtract/{d}/{PROBE_VARIANT}.tsv",
        f"results/benchmarks/cost_sim_features/{d}/vision.tsv",
        f"results/benchmarks/cost_sim_features/{d}/tactile.tsv",
        f"results/benchmarks/cost_sim_probe/{d}.tsv",
    ]


def features_setting_jobs(w):
    d = f"size~{w['size']}/arch~{w['arch']}/epochs~{w['epochs']}"
    return [
        *(f"results/benchmarks/cost_pretrain_backbone/{d}/{m}.tsv" for m in MODALITIES),
        *(f"results/benchmarks/cost_features_extract/{d}/{m}.tsv" for m in MODALITIES),
        f"results/benchmarks/cost_pretrained_vs_random/{d}.tsv",
    ]


def knob_plan(knob):
    """What the points script needs per setting: label, number, default flag, the metrics
    edge (or pretrained-vs-random table) and the benchmark files."""
    plan = []
    for label, num, is_default, w in knob_settings(knob):
        if knob in ("presses", "tactile_resolution"):
            metrics = SIM_DIR.format(**w) + "/metrics.parquet"
            jobs = sim_setting_jobs(w)
        else:
            metrics = FEAT_DIR.format(**w) + "/pretrained_vs_random.parquet"
            jobs = features_setting_jobs(w)
        plan.append(
            {
                "label": label,
                "setting": num,
                "is_default": is_default,
                "metrics": metrics,
                "benchmarks": jobs,
                "pretraining": int(w.get("epochs", 0)) > 0,
            }
        )
    return plan



def sim_corpus(w):
    """The reduced corpus of a simulation setting: the base corpus's first n samples (same
    name, seed and sample_ids), one shard, the setting's presses and tactile frame size."""
    h, wd = (int(v) for v in w.tactile.split("x"))
    return {
        "name": SIM_BASE,
        **CORPORA[SIM_BASE],
        "n": int(SIM_SWEEP["n"]),
        "shards": 1,
        "presses": int(w.presses),
        "tactile_size": [h, wd],
    }


wildcard_constraints:
    presses=r"\d+",
    tactile=r"\d+x\d+",
    size=r"\d+",
    arch="vit_[a-z]+",
    epochs=r"\d+",


rule cost_simulate_corpus:
    """A simulation setting's reduced corpus (same code path as simulate_corpus)."""
    input:
        scenes=config["scenes_file"],
        code=imports_of("simulate_corpus"),
    output:
        temp(SIM_DIR + "/shards/{shard}.parquet"),
    log:
        "results/logs/cost_simulate_corpus/presses~{presses}/tactile~{tactile}/{shard}.log",
    benchmark:
        "results/benchmarks/cost_simulate_corpus/presses~{presses}/tactile~{tactile}/{shard}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        corpus=sim_corpus,
        n_shards=1,
    script:
        "../workflow/scripts/simulate_corpus.py"


rule cost_merge_corpus:
    """The setting's corpus edge and sensor backgrounds (as merge_corpus)."""
    input:
        # a list, as merge_corpus's script expects (one shard per setting)
        shards=lambda w: [SIM_DIR.format(**w) + "/shards/0.parquet"],
        scenes=config["scenes_file"],
        code=imports_of("merge_corpus"),
    output:
        samples=SIM_DIR + "/samples.parquet",
        sensors=SIM_DIR + "/sensors.parquet",
    log:
        "results/logs/cost_merge_corpus/presses~{presses}/tactile~{tactile}.log",
    benchmark:
        "results/benchmarks/cost_merge_corpus/presses~{presses}/tactile~{tactile}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        corpus=sim_corpus,
    script:
        "../workflow/scripts/merge_corpus.py"


rule cost_background_subtract:
    """tactile_proc of the setting's corpus, the probes' variant (as background_subtract)."""
    input:
        samples=SIM_DIR + "/samples.parquet",
        sensors=SIM_DIR + "/sensors.parquet",
        code=imports_of("background_subtract"),
    output:
        SIM_DIR + "/preprocess/{variant}.parquet",
    log:
        "results/logs/cost_background_subtract/presses~{presses}/tactile~{tactile}/{variant}.log",
    benchmark:
        "results/benchmarks/cost_background_subtract/presses~{presses}/tactile~{tactile}/{variant}.tsv"
    wildcard_constraints:
        variant=one_of(VARIANTS),
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    script:
        "../workflow/scripts/background_subtract.py"


rule cost_sim_features:
    """Frozen features of the setting's frames with the config's own backbones."""
    input:
        frames=lambda w: (
            SIM_DIR + "/samples.parquet"
            if w.modality == "vision"
            else SIM_DIR + f"/preprocess/{PROBE_VARIANT}.parquet"
        ),
        weights="results/features/backbones/{modality}.pt",
        code=imports_of("extract_features"),
    output:
        SIM_DIR + "/features/{modality}.parquet",
    log:
        "results/logs/cost_sim_features/presses~{presses}/tactile~{tactile}/{modality}.log",
    benchmark:
        "results/benchmarks/cost_sim_features/presses~{presses}/tactile~{tactile}/{modality}.tsv"
    wildcard_constraints:
        modality="vision|tactile",
    threads: 1
    resources:
        mem_mb=3000,
        runtime=20,
    params:
        features=FEAT,
        column=lambda w: "rgb" if w.modality == "vision" else "tactile_proc",
    script:
        "../workflow/scripts/extract_features.py"


rule cost_sim_probe:
    """Force band width, force R² (V+T) and Δ of the force and hardness probes on one setting."""
    input:
        samples=SIM_DIR + "/samples.parquet",
        vision=SIM_DIR + "/features/vision.parquet",
        tactile=SIM_DIR + "/features/tactile.parquet",
        splits="results/corpus/splits.parquet",
        code=imports_of("cost_sim_probe"),
    output:
        SIM_DIR + "/metrics.parquet",
    log:
        "results/logs/cost_sim_probe/presses~{presses}/tactile~{tactile}.log",
    benchmark:
        "results/benchmarks/cost_sim_probe/presses~{presses}/tactile~{tactile}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=20,
    params:
        probes=config["probes"],
        corpus=SIM_BASE,
    script:
        "../workflow/scripts/cost_sim_probe.py"


rule cost_pretrain_backbone:
    """A features setting's backbone: DINO at its epochs, or the seeded random init at 0."""
    input:
        frames=lambda w: backbone_frames(w.modality, PRETRAIN["corpus"]),
        splits="results/corpus/splits.parquet",
        code=imports_of("pretrain_backbone"),
    output:
        weights=FEAT_DIR + "/backbones/{modality}.pt",
        curve=FEAT_DIR + "/backbones/{modality}_curve.parquet",
        figure=FEAT_DIR + "/backbones/{modality}_curve.png",
    log:
        "results/logs/cost_pretrain_backbone/size~{size}/arch~{arch}/epochs~{epochs}/{modality}.log",
    benchmark:
        "results/benchmarks/cost_pretrain_backbone/size~{size}/arch~{arch}/epochs~{epochs}/{modality}.tsv"
    wildcard_constraints:
        modality="vision|tactile",
    threads: 1
    resources:
        mem_mb=6000,
        runtime=120,
    params:
        backbone=lambda w: {"arch": w.arch, "checkpoint": None},
        pretrain=lambda w: {**PRETRAIN, "epochs": int(w.epochs)},
        image_size=lambda w: int(w.size),
    script:
        "../workflow/scripts/pretrain_backbone.py"


rule cost_features_extract:
    """A features setting's frozen features of the pretrained-vs-random corpus."""
    input:
        frames=lambda w: backbone_frames(w.modality, PVR["corpus"]),
        weights=FEAT_DIR + "/backbones/{modality}.pt",
        code=imports_of("extract_features"),
    output:
        FEAT_DIR + "/features/{modality}.parquet",
    log:
        "results/logs/cost_features_extract/size~{size}/arch~{arch}/epochs~{epochs}/{modality}.log",
    benchmark:
        "results/benchmarks/cost_features_extract/size~{size}/arch~{arch}/epochs~{epochs}/{modality}.tsv"
    wildcard_constraints:
        modality="vision|tactile",
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30,
    params:
        features=lambda w: {**FEAT, "image_size": int(w.size)},
        column=lambda w: "rgb" if w.modality == "vision" else "tactile_proc",
    script:
        "../workflow/scripts/extract_features.py"


rule cost_pretrained_vs_random:
    """The pretrained-vs-random check of one features setting (as pretrained_vs_random)."""
    input:
        vision=corpus_edge(PVR["corpus"]),
        tactile=backbone_frames("tactile", PVR["corpus"]),
        pretrained_vision=FEAT_DIR + "/features/vision.parquet",
        pretrained_tactile=FEAT_DIR + "/features/tactile.parquet",
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        code=imports_of("pretrained_vs_random"),
    output:
        table=FEAT_DIR + "/pretrained_vs_random.parquet",
        html=FEAT_DIR + "/pretrained_vs_random.html",
    log:
        "results/logs/cost_pretrained_vs_random/size~{size}/arch~{arch}/epochs~{epochs}.log",
    benchmark:
        "results/benchmarks/cost_pretrained_vs_random/size~{size}/arch~{arch}/epochs~{epochs}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30,
    params:
        features=lambda w: {
            **FEAT,
            "image_size": int(w.size),
            "backbones": {m: {"arch": w.arch, "checkpoint": None} for m in MODALITIES},
            "pretrain": {**PRETRAIN, "epochs": int(w.epochs)},
        },
        C=[0.1, 1.0, 10.0],
    script:
        "../workflow/scripts/pretrained_vs_random.py"


rule cost_knob_points:
    """One simulation or features knob's cost points: metric ± CI against benchmark seconds."""
    input:
        metrics=lambda w: [p["metrics"] for p in knob_plan(w.knob)],
        benchmarks=lambda w: [b for p in knob_plan(w.knob) for b in p["benchmarks"]],
        code=imports_of("cost_knob_points"),
    output:
        "results/cost/points/{knob}.parquet",
    log:
        "results/logs/cost_knob_points/{knob}.log",
    benchmark:
        "results/benchmarks/cost_knob_points/{knob}.tsv"
    wildcard_constraints:
        knob=one_of(SIM_KNOBS + FEATURE_KNOBS),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        plan=lambda w: knob_plan(w.knob),
        stage=lambda w: "corpus" if w.knob in SIM_KNOBS else "features",
        metrics=lambda w: knob_metric_ids(w.knob, config),
        n_sim=int(SIM_SWEEP["n"]),
        bootstrap=lambda w: (
            int(config["probes"]["bootstrap"]) if w.knob in SIM_KNOBS else int(PVR["bootstrap"])
        ),
    script:
        "../workflow/scripts/cost_knob_points.py"


rule cost_features_knobs:
    """Every simulation and features knob of config/cost.yaml (the rest: rules/cost.smk)."""
    input:
        expand("results/cost/points/{knob}.parquet", knob=SIM_KNOBS + FEATURE_KNOBS),
