"""Features stage: a DINOv2-architecture backbone per modality, frozen features per corpus."""

from tacgen_lib.features.settings import backbone_image_size
from tacgen_lib.plan.features import MODALITIES, VISIBILITY_EDGE, VISIBILITY_ITEMS

FEATURES = config["features"]
PRETRAIN = FEATURES["pretrain"]
PRETRAIN_CORPORA = PLANS.features.pretraining_corpora

_FEATURE_EDGES = PLANS.features.corpus_feature_edges(config)
TARGETS += _FEATURE_EDGES
EDGES += _FEATURE_EDGES
TARGETS += ["results/features/pretrained_vs_random.html"]
EDGES += expand("results/features/backbones/{m}.pt", m=MODALITIES)
EDGES += ["results/features/pretrained_vs_random.parquet"]


rule pretrain_backbone:
    """DINO, MAE (a ViT) or SimCLR (a ResNet) pretraining on the pretraining corpus's train split only, an official checkpoint, or the seeded random init."""
    input:
        frames=lambda w: PLANS.features.pretraining_frames(w.modality),
        splits="results/corpus/splits.parquet",
        code=imports_of("pretrain_backbone"),
    output:
        weights="results/features/backbones/{modality}.pt",
        curve="results/features/backbones/{modality}_curve.parquet",
    log:
        "results/logs/pretrain_backbone/{modality}.log",
    benchmark:
        "results/benchmarks/pretrain_backbone/{modality}.tsv"
    wildcard_constraints:
        modality="vision|tactile",
    priority: FIRST_PRIORITY
    conda:
        "../envs/features.yaml"
    # one thread each, so the vision and tactile runs share 2 cores side by side (measured
    # faster than one after the other at 2 threads); reruns are bit-identical per thread count
    threads: 1
    resources:
        mem_mb=6000,
        runtime=120,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        backbone=lambda w: FEATURES["backbones"][w.modality],
        pretrain=PRETRAIN,
        corpora=PRETRAIN_CORPORA,  # whose train frames DINO, MAE and SimCLR pretrain on
        # MAE's settings only where a backbone is MAE-pretrained: a change reruns only those
        mae=lambda w: (
            FEATURES["mae"]
            if FEATURES["backbones"][w.modality]["objective"] == "mae"
            else {}
        ),
        # SimCLR's settings only where a backbone is SimCLR-pretrained
        simclr=lambda w: (
            FEATURES["simclr"]
            if FEATURES["backbones"][w.modality]["objective"] == "simclr"
            else {}
        ),
        image_size=lambda w: backbone_image_size(
            FEATURES, FEATURES["backbones"][w.modality]
        ),
    script:
        "../workflow/scripts/pretrain_backbone.py"


rule extract_vision_features:
    """Frozen vision backbone (CLS or mean-patch) and pixel-V for every RGB frame of a corpus."""
    input:
        frames=corpus_edge("{corpus}"),
        weights="results/features/backbones/vision.pt",
        code=imports_of("extract_features"),
    output:
        feature_edge("{corpus}", "vision"),
    log:
        "results/logs/extract_features/{corpus}/vision.log",
    benchmark:
        "results/benchmarks/extract_features/{corpus}/vision.tsv"
    wildcard_constraints:
        # natural corpora between the rho grid's ends share the ends' features (below)
        corpus=none_of(NATURAL_BETWEEN),
    priority: PLANS.features.extraction_priority
    conda:
        "../envs/features.yaml"
    threads: PLANS.features.extraction_threads  # config features.threads (1: two jobs side by side)
    resources:
        mem_mb=4000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        features=FEATURES,
        column="rgb",
    script:
        "../workflow/scripts/extract_features.py"


rule extract_tactile_features:
    """Frozen tactile backbone and pixel-T for every background-subtracted frame of one variant."""
    input:
        frames="results/preprocess/{corpus}/{variant}.parquet",
        weights="results/features/backbones/tactile.pt",
        code=imports_of("extract_features"),
    output:
        feature_edge("{corpus}", "tactile", "{variant}"),
    log:
        "results/logs/extract_features/{corpus}/tactile~{variant}.log",
    benchmark:
        "results/benchmarks/extract_features/{corpus}/tactile~{variant}.tsv"
    wildcard_constraints:
        # the rho grid's natural corpora after the first share its features (below)
        corpus=none_of(NATURAL_GRID[1:]),
        variant=one_of(VARIANTS),
    priority: PLANS.features.extraction_priority
    conda:
        "../envs/features.yaml"
    threads: PLANS.features.extraction_threads  # config features.threads (1: two jobs side by side)
    resources:
        mem_mb=4000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        features=FEATURES,
        column="tactile_proc",
    script:
        "../workflow/scripts/extract_features.py"


rule share_natural_touch:
    """The tactile features of a natural corpus of the regime's rho grid, shared from the grid's first corpus: their touch is simulated once, byte-identical (checked sample by sample)."""
    input:
        features=feature_edge(
            NATURAL_GRID[0] if NATURAL_GRID else "none", "tactile", "{variant}"
        ),
        source=corpus_edge(NATURAL_GRID[0] if NATURAL_GRID else "none"),
        target=corpus_edge("{corpus}"),
        code=imports_of("share_natural_touch"),
    output:
        feature_edge("{corpus}", "tactile", "{variant}"),
    log:
        "results/logs/share_natural_touch/{corpus}/tactile~{variant}.log",
    benchmark:
        "results/benchmarks/share_natural_touch/{corpus}/tactile~{variant}.tsv"
    wildcard_constraints:
        corpus=one_of(NATURAL_GRID[1:]),
        variant=one_of(VARIANTS),
    priority: CHAIN_PRIORITY
    conda:
        "../envs/corpus.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    script:
        "../workflow/scripts/share_natural_touch.py"


rule share_natural_vision:
    """The vision features of a natural corpus between the regime's rho grid's ends, shared from the ends (rho 0 and 1): each sample looks as in one of them, its RGB frame byte-identical (checked sample by sample)."""
    input:
        features=[feature_edge(c, "vision") for c in NATURAL_ENDS],
        sources=[corpus_edge(c) for c in NATURAL_ENDS],
        target=corpus_edge("{corpus}"),
        code=imports_of("share_natural_vision"),
    output:
        feature_edge("{corpus}", "vision"),
    log:
        "results/logs/share_natural_vision/{corpus}.log",
    benchmark:
        "results/benchmarks/share_natural_vision/{corpus}.tsv"
    wildcard_constraints:
        corpus=one_of(NATURAL_BETWEEN),
    conda:
        "../envs/corpus.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    script:
        "../workflow/scripts/share_natural_vision.py"


rule pretrained_vs_random:
    """Linear probes on pretrained vs random-init backbone features, with a bootstrap CI."""
    input:
        vision=corpus_edge(FEATURES["pretrained_vs_random"]["corpus"]),
        tactile=PLANS.features.backbone_frames(
            "tactile", FEATURES["pretrained_vs_random"]["corpus"]
        ),
        pretrained_vision=feature_edge(
            FEATURES["pretrained_vs_random"]["corpus"], "vision"
        ),
        pretrained_tactile=feature_edge(
            FEATURES["pretrained_vs_random"]["corpus"], "tactile", PRETRAIN["variant"]
        ),
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        code=imports_of("pretrained_vs_random"),
    output:
        table="results/features/pretrained_vs_random.parquet",
        html=features_report_item(
            "results/features/pretrained_vs_random.html",
            "../workflow/report/pretrained_vs_random.rst",
            {"table": "pretrained vs random init"},
            FEATURES_SHOWN,
        ),
    log:
        "results/logs/pretrained_vs_random.log",
    benchmark:
        "results/benchmarks/pretrained_vs_random.tsv"
    conda:
        "../envs/features.yaml"
    threads: FEATURES["threads"]  # extracts random-init backbone features
    resources:
        mem_mb=4000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        features=FEATURES,
        pretrain=PRETRAIN,
        check=FEATURES["pretrained_vs_random"],
        archs={m: FEATURES["backbones"][m]["arch"] for m in ("vision", "tactile")},
        C=[0.1, 1.0, 10.0],
    script:
        "../workflow/scripts/pretrained_vs_random.py"


# what V sees (tacgen_lib.generate.visibility): every simulated corpus's visible factors
# decoded from its vision features; the report page What vision sees and the regime's gate
VISIBILITY = FEATURES["visibility"]  # the schema fills its defaults
# every simulated corpus, and of the regime's rho grid its first corpus only: at every rho
# the appearance class is uniform and a frame depends on its look (colour, texture, shape,
# size, jitter, pose), never on the material (tacgen_lib.corpus.sim.samples), so each corpus of
# the grid would estimate the same accuracies; the grid's gate reads the first corpus's rows
VISIBILITY_CORPORA = [c for c in SIM_CORPORA if c not in NATURAL_GRID[1:]]
if SIM_CORPORA:
    EDGES.append(VISIBILITY_EDGE)
    TARGETS += [
        f"results/report/visibility/{n}.{e}" for n, e in VISIBILITY_ITEMS.items()
    ]


rule visibility_check:
    """How well V decodes each factor a simulated frame shows (colour, texture, shape, size, the natural design's appearance class), with a linear and a nonlinear probe on every non-test row."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        v=[feature_edge(c, "vision") for c in VISIBILITY_CORPORA],
        code=imports_of("visibility_check"),
    output:
        **{
            name: report(
                f"results/report/visibility/{name}.{ext}",
                caption=f"../workflow/report/visibility_{name}.rst",
                category=category("What vision sees"),
                labels={"item": name},
            )
            for name, ext in VISIBILITY_ITEMS.items()
        },
        edge=VISIBILITY_EDGE,
    log:
        "results/logs/visibility_check.log",
    benchmark:
        "results/benchmarks/visibility_check.tsv"
    conda:
        "../envs/probes.yaml"
    threads: 2  # its (corpus, factor, probe) fits in forked one-thread workers (runtime.workers)
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        corpora=VISIBILITY_CORPORA,  # the order of the v inputs
        # corpora of the natural design: their appearance_id is the appearance class
        natural=[c for c in VISIBILITY_CORPORA if CORPORA[c].get("design") == "natural"],
        visibility=VISIBILITY,
        probes=PROBE_SETTINGS,
        probe_seed=config["probes"]["seeds"][0],
    script:
        "../workflow/scripts/visibility_check.py"
