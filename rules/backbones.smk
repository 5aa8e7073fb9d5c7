"""Backbone families (tacgen_lib.features.families): each family's frozen backbones, their
features on the probe corpora, V vs V+T under the linear and the 2-layer probe, and the report
page Backbone families. The main family (the main DAG's backbones) reads the main feature
edges, and its rows are the probes stage's headline rows where that stage made them."""


include: "backbones_common.smk"


localrules:
    aggregate_backbones,


rule family_backbone:
    """One family's frozen backbone of a modality (checkpoint, MAE or DINO pretraining on the pretraining corpus's train split, or the seeded random init) and its features of every frame of each probe corpus."""
    input:
        frames=lambda w: PLANS.features.pretraining_frames(
            w.modality, PLANS.families.spec(w.family, w.modality)
        ),
        splits="results/corpus/splits.parquet",
        extract=lambda w: PLANS.families.frames(w.modality),
        code=imports_of("pretrain_backbone"),
    output:
        weights="results/features/families/{family}/{modality}.pt",
        curve="results/features/families/{family}/{modality}_curve.parquet",
        features=[
            f"results/features/families/{{family}}/{c}/{{modality}}.parquet"
            for c in PLANS.families.corpora
        ],
    log:
        "results/logs/family_backbone/{family}/{modality}.log",
    benchmark:
        "results/benchmarks/family_backbone/{family}/{modality}.tsv"
    wildcard_constraints:
        family=one_of(PLANS.families.own or ["-"]),
        modality="vision|tactile",
    conda:
        "../envs/features.yaml"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        backbone=lambda w: PLANS.families.settings.families[w.family][
            w.modality
        ].__dict__,
        pretrain=PRETRAIN,
        corpora=PRETRAIN_CORPORA,  # whose train frames DINO, MAE and SimCLR pretrain on
        mae=lambda w: (
            FEATURES["mae"]
            if PLANS.families.spec(w.family, w.modality).objective == "mae"
            else {}
        ),
        # SimCLR's settings only where a backbone is SimCLR-pretrained
        simclr=lambda w: (
            FEATURES["simclr"]
            if PLANS.families.spec(w.family, w.modality).objective == "simclr"
            else {}
        ),
        image_size=lambda w: backbone_image_size(
            FEATURES, PLANS.families.settings.families[w.family][w.modality].__dict__
        ),
        batch_size=FEATURES["batch_size"],
        pool=lambda w: PLANS.families.spec(w.family, w.modality).pool
        or FEATURES["pool"],
    script:
        "../workflow/scripts/pretrain_backbone.py"


rule family_probe:
    """V vs V+T (concat) of every probe family of backbones.probes on one backbone family's features, linear and 2-layer, each with its fixed-test bootstrap CI."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        vision=lambda w: [
            PLANS.families.features_edge(w.family, c, "vision")
            for c in PLANS.families.corpora
        ],
        tactile=lambda w: [
            PLANS.families.features_edge(w.family, c, "tactile")
            for c in PLANS.families.corpora
        ],
        code=imports_of("family_probe"),
    output:
        rows=FAMILY_PROBE,
    log:
        "results/logs/family_probe/{family}.log",
    benchmark:
        "results/benchmarks/family_probe/{family}.tsv"
    wildcard_constraints:
        family=one_of(PLANS.families.computed or ["-"]),
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        probes={p: PROBES["families"][p] for p in PLANS.families.settings.probes},
        corpora={c: CORPORA[c] for c in PLANS.families.corpora},
        settings=PROBE_SETTINGS,
        protocols=PLANS.families.settings.protocols,
        seed=PROBES["seeds"][0],
        labels=lambda w: PLANS.families.labels(w.family),
    script:
        "../workflow/scripts/family_probe.py"


rule aggregate_backbones:
    """Every family's probes; the report page Backbone families."""
    input:
        rows=[FAMILY_PROBE.format(family=f) for f in PLANS.families.computed],
        main=[
            f"{PROBE_DIR}/seed~{PROBES['seeds'][0]}.parquet".format(
                family=p, protocol=q
            )
            for f in PLANS.families.main_from_probes
            for p, q in PLANS.families.jobs
        ],
        code=imports_of("aggregate_backbones"),
    output:
        table=report(
            "results/report/backbones/table.html",
            caption="../workflow/report/backbones_table.rst",
            category=category("Backbone families"),
            labels={"item": "V vs V+T per family"},
        ),
        summary="results/backbones/summary.parquet",
    log:
        "results/logs/aggregate_backbones.log",
    benchmark:
        "results/benchmarks/aggregate_backbones.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        order=list(PLANS.families.settings.run),
        main={f: PLANS.families.labels(f) for f in PLANS.families.main_from_probes},
        main_jobs=PLANS.families.jobs,
        heads_variant=PLANS.families.variant,
    script:
        "../workflow/scripts/aggregate_backbones.py"
