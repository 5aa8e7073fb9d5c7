"""Pixel-space V->T generators (tacgen_lib.generate.pixel): a Pix2Pix translator and a pixel
U-Net DDPM with classifier-free guidance, RGB -> background-subtracted tactile frame.

train_pixel_generator (per corpus x generator x seed, train rows only) -> sample_pixel_generator
(per arm: every row's frame, its train-fitted contrast calibration, the frozen tactile ViT's
features of both) -> evaluate_pixel_generators (reconstruction and utility of every arm on the
same test rows) and pixel_curve_point (InfoNCE heads retrained with generated touch on a
fraction p of their rows, probed on real touch) -> aggregate_pixel (summary and the page).
"""


include: "pixel_common.smk"


rule train_pixel_generator:
    """A pixel generator (Pix2Pix or the pixel DDPM) of the clip128 tactile frame from the RGB frame, on one corpus's train rows, early-stopped on val."""
    input:
        samples=lambda w: corpus_edge(w.corpus),
        tactile=lambda w: f"results/preprocess/{w.corpus}/clip128.parquet",
        splits="results/corpus/splits.parquet",
        code=imports_of("train_pixel_generator"),
    output:
        weights=f"{PIXEL_GENERATOR}/generator.safetensors",
        curve=f"{PIXEL_GENERATOR}/curve.parquet",
    log:
        "results/logs/train_pixel_generator/{corpus}/{generator}/{seed}.log",
    benchmark:
        "results/benchmarks/train_pixel_generator/{corpus}/{generator}/{seed}.tsv"
    wildcard_constraints:
        corpus=one_of(PIXEL_TRAIN_CORPORA),
        generator=one_of(GENERATORS),
        seed=r"\d+",
    conda:
        "../envs/generate.yaml"
    # one thread: the two generators train side by side on two cores
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=PIXEL,
    script:
        "../workflow/scripts/train_pixel_generator.py"


rule sample_pixel_generator:
    """Every row's generated tactile frame for one arm, its contrast calibration fitted on train rows, and the frozen tactile ViT's features of both."""
    input:
        weights=lambda w: f"{PIXEL_GENERATOR}/generator.safetensors".format(
            corpus=w.corpus, generator=arm_generator_name(w.arm), seed=w.seed
        ),
        samples=lambda w: corpus_edge(w.corpus),
        tactile=lambda w: f"results/preprocess/{w.corpus}/clip128.parquet",
        splits="results/corpus/splits.parquet",
        backbone="results/features/backbones/tactile.pt",
        code=imports_of("sample_pixel_generator"),
    output:
        frames=PIXEL_ARM,
    log:
        "results/logs/sample_pixel_generator/{corpus}/{arm}/{seed}.log",
    benchmark:
        "results/benchmarks/sample_pixel_generator/{corpus}/{arm}/{seed}.tsv"
    wildcard_constraints:
        corpus=one_of(PIXEL_TRAIN_CORPORA),
        arm=one_of(PIXEL_JUDGED_ARMS),
        seed=r"\d+",
    conda:
        "../envs/generate.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=PIXEL,
        features=config["features"],
    script:
        "../workflow/scripts/sample_pixel_generator.py"


rule evaluate_pixel_generators:
    """Reconstruction (pixel-L2, SSIM, contrast, texture) and utility (V + T_gen against V, nonlinear V, ridge V->T, shuffled pairing) of every arm on the same test rows."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        v=lambda w: feature_edge(w.corpus, "vision"),
        t=lambda w: feature_edge(w.corpus, "tactile", "clip128"),
        tactile=lambda w: f"results/preprocess/{w.corpus}/clip128.parquet",
        backbone="results/features/backbones/tactile.pt",
        baselines=lambda w: BASELINES.format(corpus=w.corpus),
        arms=lambda w: [
            PLANS.pixel.arm_edge(w.corpus, a, w.seed) for a in PIXEL_JUDGED_ARMS
        ],
        code=imports_of("evaluate_pixel_generators"),
    output:
        rows=f"{PIXEL_EVAL}/evaluation.parquet",
        permutations=f"{PIXEL_EVAL}/permutations.parquet",
        reconstruction=f"{PIXEL_EVAL}/reconstruction.parquet",
    log:
        "results/logs/evaluate_pixel_generators/{corpus}/{seed}.log",
    benchmark:
        "results/benchmarks/evaluate_pixel_generators/{corpus}/{seed}.tsv"
    wildcard_constraints:
        corpus=one_of(PIXEL_CORPORA),
        seed=r"\d+",
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=PIXEL,
        arms=PIXEL_JUDGED_ARMS,  # the order of the arms inputs
        features=config["features"],
        generate=config["generate"],
        targets=lambda w: PIXEL["corpora"][w.corpus],
        corpus=lambda w: CORPORA[w.corpus],
        probes=PROBE_SETTINGS,
        grids=GENERATE_GRIDS,
        probe_seed=config["probes"]["seeds"][0],
    script:
        "../workflow/scripts/evaluate_pixel_generators.py"


rule pixel_curve_point:
    """InfoNCE heads retrained with generated touch in place of real on a fraction p of their rows (and the shuffled-generator control), probed on real held-out touch."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        v=lambda w: feature_edge(w.corpus, "vision"),
        t=lambda w: feature_edge(w.corpus, "tactile", "clip128"),
        t_gen=lambda w: PLANS.pixel.arm_edge(w.corpus, PIXEL_CURVE_ARM, w.seed),
        code=imports_of("pixel_curve_point"),
    output:
        PIXEL_POINT,
    log:
        "results/logs/pixel_curve_point/{corpus}/{seed}_{fraction}.log",
    benchmark:
        "results/benchmarks/pixel_curve_point/{corpus}/{seed}_{fraction}.tsv"
    wildcard_constraints:
        corpus=one_of(PIXEL_CURVE_CORPORA),
        seed=r"\d+",
        fraction=one_of([fraction_text(p) for p in PIXEL_CURVE["fractions"]]),
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        align=config["align"],
        tau=config["probes"]["heads"]["tau"],
        arm=PIXEL_CURVE_ARM,
        targets=lambda w: PIXEL_CURVE["corpora"][w.corpus],
        corpus=lambda w: CORPORA[w.corpus],
        probes=PROBE_SETTINGS,
        grids=GENERATE_GRIDS,
        probe_seed=config["probes"]["seeds"][0],
    script:
        "../workflow/scripts/pixel_curve_point.py"


rule aggregate_pixel:
    """The pixel generators' summary and page: the architecture table, filmstrips, the p-curve, reconstruction against utility."""
    input:
        rows=PLANS.pixel.eval_files("evaluation.parquet"),
        reconstruction=PLANS.pixel.eval_files("reconstruction.parquet"),
        points=PLANS.pixel.points(),
        frames=(
            [
                PLANS.pixel.arm_edge(PIXEL_CORPORA[0], a, PLANS.pixel.seeds()[0])
                for a in PIXEL_JUDGED_ARMS
            ]
            if PIXEL_CORPORA
            else []
        ),
        samples=corpus_edge(PIXEL_CORPORA[0]) if PIXEL_CORPORA else [],
        tactile=(
            f"results/preprocess/{PIXEL_CORPORA[0]}/clip128.parquet"
            if PIXEL_CORPORA
            else []
        ),
        splits="results/corpus/splits.parquet",
        train_bench=PLANS.pixel.benchmarks("train_pixel_generator"),
        sample_bench=PLANS.pixel.benchmarks("sample_pixel_generator"),
        curves=[
            w.replace("generator.safetensors", "curve.parquet")
            for w in PLANS.pixel.weights()
        ],
        latent="results/generate/evaluation.parquet",
        code=imports_of("aggregate_pixel"),
    output:
        **{
            name: report(
                f"{PIXEL_REPORT}/{name}.{ext}",
                caption=f"../workflow/report/pixel_{name}.rst",
                category=category("Pixel generators"),
                subcategory="Figures" if ext == "png" else "Tables",
                labels={"item": name},
            )
            for name, ext in PIXEL_ITEMS.items()
        },
        summary="results/pixel/summary.parquet",
    log:
        "results/logs/aggregate_pixel.log",
    benchmark:
        "results/benchmarks/aggregate_pixel.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        arms=PIXEL_JUDGED_ARMS,
        corpus=PIXEL_CORPORA[0] if PIXEL_CORPORA else "",
        seed=PLANS.pixel.seeds()[0] if PLANS.pixel.seeds() else "",
        size=PIXEL.get("size"),
        latent_ref=PLANS.generate.reference(),
    script:
        "../workflow/scripts/aggregate_pixel.py"
