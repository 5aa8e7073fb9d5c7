"""Generate stage: a latent V->T diffusion generator per corpus x seed, sampled over the
guidance x steps x sampler grid, judged by what generated touch adds to the probes.

train_generator -> sample_generator (every cell of one generator in one job) -> evaluate_generator (every cell of one
generator in one job) -> aggregate_generate (summary + report). The probes no generator
changes (V, V+T_real, the nonlinear V baseline) are fitted once per corpus by
fit_generator_baselines, beside training, and shared by every seed's evaluate_generator.
"""


include: "generate_common.smk"


TARGETS += ["results/generate/summary.parquet"]
TARGETS += [f"{GENERATE_REPORT}/{n}.{e}" for n, e in GENERATE_ITEMS.items()]
EDGES += ["results/generate/evaluation.parquet"]
EDGES += [BASELINES.format(corpus=c) for c in BASELINE_CORPORA]
EDGES += PLANS.generate.generator_files(f"{GENERATOR}/generator.arrow")
EDGES += PLANS.generate.generator_files(f"{GENERATOR}/curve.parquet")
EDGES += PLANS.generate.generator_files(f"{GENERATOR}/evaluation.parquet")
EDGES += PLANS.generate.generator_files(f"{GENERATOR}/permutations.parquet")
EDGES += [sample_edge(*cell) for cell in PLANS.generate.all_sample_cells()]


localrules:
    aggregate_generate,


rule train_generator:
    """Residual-MLP diffusion model of T given V on one corpus's train split, early-stopped on val."""
    input:
        v=lambda w: feature_edge(w.corpus, "vision"),
        t=lambda w: PLANS.generate.tactile(w.corpus),
        splits="results/corpus/splits.parquet",
        code=imports_of("train_generator"),
    output:
        weights=f"{GENERATOR}/generator.arrow",
        curve=f"{GENERATOR}/curve.parquet",
    log:
        "results/logs/train_generator/{corpus}/{seed}.log",
    benchmark:
        "results/benchmarks/train_generator/{corpus}/{seed}.tsv"
    wildcard_constraints:
        corpus=one_of(GENERATE_CORPORA),
        seed=SAMPLE_CONSTRAINTS["seed"],
    priority: CHAIN_PRIORITY  # FIRST_PRIORITY's comment (rules/common.smk)
    conda:
        "../envs/generate.yaml"
    # one thread: the default model's GEMMs (128 x 256 x 256) gain little from a second
    # thread, so two generators training side by side finish sooner than one after the other
    # (profiles/slurm gives it 2 on a cluster; results are bit-reproducible per thread count)
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=GENERATE,  # the whole subtree; tacgen_lib.generate.settings reads it
    script:
        "../workflow/scripts/train_generator.py"


rule sample_generator:
    """Generated tactile features for every row of the corpus, every sampling cell of one generator: loaded once, its cells on the job's threads."""
    input:
        weights=f"{GENERATOR}/generator.arrow",
        v=lambda w: feature_edge(w.corpus, "vision"),
        code=imports_of("sample_generator"),
    output:
        t_gen=generator_cells(f"{SAMPLE_CELL}/t_gen.parquet", GENERATE_CELLS),
        # each cell's seconds (the job times its cells; the Generation summary and the cost
        # page read them as they read a benchmark file)
        seconds=generator_cells(SAMPLE_SECONDS, GENERATE_CELLS),
    log:
        "results/logs/sample_generator/{corpus}/{seed}.log",
    benchmark:
        "results/benchmarks/sample_generator/{corpus}/{seed}.tsv"
    wildcard_constraints:
        corpus=one_of(GENERATE_CORPORA),
        seed=SAMPLE_CONSTRAINTS["seed"],
    conda:
        "../envs/generate.yaml"
    # one thread: on a workstation the generators' jobs share its cores (profiles/slurm gives
    # each more: its cells in one-thread workers, the same edges at any thread count)
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=GENERATE,
        cells=GENERATE_CELLS,  # the order of the outputs
    script:
        "../workflow/scripts/sample_generator.py"


rule fit_generator_baselines:
    """V alone, V+T_real and the nonlinear V baseline of one corpus: the probes every generator seed (latent or pixel) shares."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        v=lambda w: feature_edge(w.corpus, "vision"),
        t=lambda w: PLANS.generate.tactile(w.corpus),
        code=imports_of("fit_generator_baselines"),
    output:
        baselines=BASELINES,
    log:
        "results/logs/fit_generator_baselines/{corpus}.log",
    benchmark:
        "results/benchmarks/fit_generator_baselines/{corpus}.tsv"
    wildcard_constraints:
        corpus=one_of(BASELINE_CORPORA),
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        # only what these probes read: a generator knob must not refit them
        gammas=GENERATE["nonlinear_gammas"],
        cv_repeats=GENERATE["cv_repeats"],
        targets=lambda w: BASELINE_TARGETS[w.corpus],
        corpus=lambda w: CORPORA[w.corpus],
        probes=PROBE_SETTINGS,
        grids=GENERATE_GRIDS,
        probe_seed=config["probes"]["seeds"][0],
    script:
        "../workflow/scripts/fit_generator_baselines.py"


rule evaluate_generator:
    """V+T_gen (shuffled, vs the corpus's baselines, fidelity) for every cell of one generator."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        v=lambda w: feature_edge(w.corpus, "vision"),
        t=lambda w: PLANS.generate.tactile(w.corpus),
        baselines=lambda w: BASELINES.format(corpus=w.corpus),
        t_gen=lambda w: [
            sample_edge(w.corpus, w.seed, *cell) for cell in GENERATE_CELLS
        ],
        code=imports_of("evaluate_generator"),
    output:
        rows=f"{GENERATOR}/evaluation.parquet",
        permutations=f"{GENERATOR}/permutations.parquet",
    log:
        "results/logs/evaluate_generator/{corpus}/{seed}.log",
    benchmark:
        "results/benchmarks/evaluate_generator/{corpus}/{seed}.tsv"
    wildcard_constraints:
        corpus=one_of(GENERATE_CORPORA),
        seed=SAMPLE_CONSTRAINTS["seed"],
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        settings=GENERATE,
        targets=lambda w: GENERATE["corpora"][w.corpus],
        corpus=lambda w: CORPORA[w.corpus],
        probes=PROBE_SETTINGS,
        grids=GENERATE_GRIDS,
        probe_seed=config["probes"]["seeds"][0],
        cells=GENERATE_CELLS,  # the order of the t_gen inputs
        reference=PLANS.generate.reference_cell(),  # its CV chooses the logistic C of every cell
        # the generated-touch rows a page compares per corpus x target (family-wise CIs)
        family=family_size(len(GENERATE_CELLS), len(GENERATE["seeds"])),
    script:
        "../workflow/scripts/evaluate_generator.py"


rule aggregate_generate:
    """One summary of every generator and cell with its wall times; the Generation report."""
    input:
        rows=PLANS.generate.generator_files(f"{GENERATOR}/evaluation.parquet"),
        permutations=PLANS.generate.generator_files(f"{GENERATOR}/permutations.parquet"),
        curves=PLANS.generate.generator_files(f"{GENERATOR}/curve.parquet"),
        train_bench=[
            f"results/benchmarks/train_generator/{c}/{s}.tsv"
            for c, s in PLANS.generate.generators()
        ],
        sample_bench=[
            sample_benchmark(*cell) for cell in PLANS.generate.all_sample_cells()
        ],
        splits="results/corpus/splits.parquet",
        pca_real=PLANS.generate.tactile(GENERATE_CORPORA[0]),
        pca_gen=sample_edge(
            GENERATE_CORPORA[0],
            GENERATE["seeds"][0],
            PLANS.generate.reference()["sampler"],
            PLANS.generate.reference()["guidance"],
            PLANS.generate.reference()["steps"],
        ),
        code=imports_of("aggregate_generate"),
    output:
        **{
            name: report(
                f"{GENERATE_REPORT}/{name}.{ext}",
                caption=f"../workflow/report/generate_{name}.rst",
                category=category("Generation"),
                subcategory="Figures" if ext == "png" else "Tables",
                labels={"item": name},
            )
            for name, ext in GENERATE_ITEMS.items()
        },
        summary="results/generate/summary.parquet",
        evaluation="results/generate/evaluation.parquet",
    log:
        "results/logs/aggregate_generate.log",
    benchmark:
        "results/benchmarks/aggregate_generate.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        ref=PLANS.generate.reference(),
        generators=PLANS.generate.generators(),
        sample_cells=PLANS.generate.all_sample_cells(),
        pca_corpus=GENERATE_CORPORA[0],
        pca_seed=GENERATE["seeds"][0],
    script:
        "../workflow/scripts/aggregate_generate.py"
