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


include: "cost_features_common.smk"


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
        temp(
            "results/cost/sim/presses~{presses}/tactile~{tactile}/shards/{shard}.parquet"
        ),
    log:
        "results/logs/cost_simulate_corpus/presses~{presses}/tactile~{tactile}/{shard}.log",
    benchmark:
        "results/benchmarks/cost_simulate_corpus/presses~{presses}/tactile~{tactile}/{shard}.tsv"
    conda:
        "../envs/corpus.yaml"
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
        shards=lambda w: [sim_path(w, "shards/0.parquet")],
        scenes=config["scenes_file"],
        code=imports_of("merge_corpus"),
    output:
        samples="results/cost/sim/presses~{presses}/tactile~{tactile}/samples.parquet",
        sensors="results/cost/sim/presses~{presses}/tactile~{tactile}/sensors.parquet",
    log:
        "results/logs/cost_merge_corpus/presses~{presses}/tactile~{tactile}.log",
    benchmark:
        "results/benchmarks/cost_merge_corpus/presses~{presses}/tactile~{tactile}.tsv"
    conda:
        "../envs/corpus.yaml"
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
        samples="results/cost/sim/presses~{presses}/tactile~{tactile}/samples.parquet",
        sensors="results/cost/sim/presses~{presses}/tactile~{tactile}/sensors.parquet",
        code=imports_of("background_subtract"),
    output:
        "results/cost/sim/presses~{presses}/tactile~{tactile}/preprocess/{variant}.parquet",
    log:
        "results/logs/cost_background_subtract/presses~{presses}/tactile~{tactile}/{variant}.log",
    benchmark:
        "results/benchmarks/cost_background_subtract/presses~{presses}/tactile~{tactile}/{variant}.tsv"
    wildcard_constraints:
        variant=one_of(VARIANTS),
    conda:
        "../envs/features.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    script:
        "../workflow/scripts/background_subtract.py"


rule cost_sim_features:
    """Frozen features of the setting's frames with the config's own backbones."""
    input:
        frames=lambda w: sim_path(
            w,
            (
                "samples.parquet"
                if w.modality == "vision"
                else f"preprocess/{PROBE_VARIANT}.parquet"
            ),
        ),
        weights="results/features/backbones/{modality}.pt",
        code=imports_of("extract_features"),
    output:
        "results/cost/sim/presses~{presses}/tactile~{tactile}/features/{modality}.parquet",
    log:
        "results/logs/cost_sim_features/presses~{presses}/tactile~{tactile}/{modality}.log",
    benchmark:
        "results/benchmarks/cost_sim_features/presses~{presses}/tactile~{tactile}/{modality}.tsv"
    wildcard_constraints:
        modality="vision|tactile",
    conda:
        "../envs/features.yaml"
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
        samples="results/cost/sim/presses~{presses}/tactile~{tactile}/samples.parquet",
        vision="results/cost/sim/presses~{presses}/tactile~{tactile}/features/vision.parquet",
        tactile="results/cost/sim/presses~{presses}/tactile~{tactile}/features/tactile.parquet",
        splits="results/corpus/splits.parquet",
        code=imports_of("cost_sim_probe"),
    output:
        "results/cost/sim/presses~{presses}/tactile~{tactile}/metrics.parquet",
    log:
        "results/logs/cost_sim_probe/presses~{presses}/tactile~{tactile}.log",
    benchmark:
        "results/benchmarks/cost_sim_probe/presses~{presses}/tactile~{tactile}.tsv"
    conda:
        "../envs/probes.yaml"
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
        weights="results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}/backbones/{modality}.pt",
        curve="results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}/backbones/{modality}_curve.parquet",
    log:
        "results/logs/cost_pretrain_backbone/size~{size}/arch~{arch}/epochs~{epochs}/{modality}.log",
    benchmark:
        "results/benchmarks/cost_pretrain_backbone/size~{size}/arch~{arch}/epochs~{epochs}/{modality}.tsv"
    wildcard_constraints:
        modality="vision|tactile",
    conda:
        "../envs/features.yaml"
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
        weights="results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}/backbones/{modality}.pt",
        code=imports_of("extract_features"),
    output:
        "results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}/features/{modality}.parquet",
    log:
        "results/logs/cost_features_extract/size~{size}/arch~{arch}/epochs~{epochs}/{modality}.log",
    benchmark:
        "results/benchmarks/cost_features_extract/size~{size}/arch~{arch}/epochs~{epochs}/{modality}.tsv"
    wildcard_constraints:
        modality="vision|tactile",
    conda:
        "../envs/features.yaml"
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
        pretrained_vision="results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}/features/vision.parquet",
        pretrained_tactile="results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}/features/tactile.parquet",
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        code=imports_of("pretrained_vs_random"),
    output:
        table="results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}/pretrained_vs_random.parquet",
        html="results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}/pretrained_vs_random.html",
    log:
        "results/logs/cost_pretrained_vs_random/size~{size}/arch~{arch}/epochs~{epochs}.log",
    benchmark:
        "results/benchmarks/cost_pretrained_vs_random/size~{size}/arch~{arch}/epochs~{epochs}.tsv"
    conda:
        "../envs/features.yaml"
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
    conda:
        "../envs/report.yaml"
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
            int(config["probes"]["bootstrap"])
            if w.knob in SIM_KNOBS
            else int(PVR["bootstrap"])
        ),
    script:
        "../workflow/scripts/cost_knob_points.py"


rule cost_features_knobs:
    """Every simulation and features knob of config/cost.yaml (the rest: rules/cost.smk)."""
    input:
        expand("results/cost/points/{knob}.parquet", knob=SIM_KNOBS + FEATURE_KNOBS),
