"""Cost of accuracy: sweeps of the align, probes, generator and policy knobs, and the page.

`snakemake --cores 2 cost_of_accuracy --configfile config/cost.yaml` runs every knob listed in
config cost.knobs around the default and draws the page; the default run draws it from the
knobs its own grids already vary (generator steps and samplers, the policy sweep).
"""


include: "cost_sweep_common.smk"


# ------------------------------------------------------------------ alignment knobs


rule cost_train_heads:
    """InfoNCE heads at one setting of an alignment knob and one seed; test retrieval ranks."""
    input:
        v=lambda w: feature_edge(cost_align(w.knob)[0], "vision"),
        t=lambda w: feature_edge(
            cost_align(w.knob)[0], "tactile", cost_align(w.knob)[1]
        ),
        splits="results/corpus/splits.parquet",
        code=imports_of("cost_train_heads"),
    output:
        ranks="results/cost/align/{knob}/{value}/seed~{seed}/ranks.parquet",
    log:
        "results/logs/cost_train_heads/{knob}/{value}/{seed}.log",
    benchmark:
        "results/benchmarks/cost_train_heads/{knob}/{value}/{seed}.tsv"
    wildcard_constraints:
        knob=one_of(ALIGN_KNOBS),
        value=r"all|[1-9]\d*",
        seed=r"0|[1-9]\d*",
    conda:
        "../envs/align.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=60,
    params:
        settings=ALIGN,
        corpus=lambda w: cost_align(w.knob)[0],
        tau=config["probes"]["heads"]["tau"],
        n_train=str(config["probes"]["heads"]["n_train"]),
    script:
        "../workflow/scripts/cost_train_heads.py"


rule cost_align_points:
    """Points of an alignment knob: top-1 and median rank with a bootstrap CI, and seconds."""
    input:
        ranks=cost_align_files(
            "results/cost/align/{knob}/{value}/seed~{seed}/ranks.parquet"
        ),
        benchmarks=cost_align_files(
            "results/benchmarks/cost_train_heads/{knob}/{value}/{seed}.tsv"
        ),
        code=imports_of("cost_align_points"),
    output:
        points=COST_POINTS,
    log:
        "results/logs/cost_align_points/{knob}.log",
    benchmark:
        "results/benchmarks/cost_align_points/{knob}.tsv"
    wildcard_constraints:
        knob=one_of(ALIGN_KNOBS),
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        cells=lambda w: cost_align_cells(w.knob),
        default=lambda w: (
            None
            if w.knob == "align_steps"
            else str(DEFAULT_CONFIG["probes"]["heads"]["n_train"])
        ),
        bootstrap=lambda w: cost_knob(w.knob).get("bootstrap", 2000),
    script:
        "../workflow/scripts/cost_align_points.py"


# ------------------------------------------------------------------ probe knobs


rule cost_probe:
    """One replicate seed of a probe knob's setting: B bootstrap resamples or permutations."""
    input:
        unpack(cost_probe_inputs),
        code=imports_of("cost_probe"),
    output:
        rows="results/cost/probes/{knob}/{value}/rep~{rep}.parquet",
    log:
        "results/logs/cost_probe/{knob}/{value}/{rep}.log",
    benchmark:
        "results/benchmarks/cost_probe/{knob}/{value}/{rep}.tsv"
    wildcard_constraints:
        knob=one_of(PROBE_KNOBS),
        value=r"[1-9]\d*",
        rep=r"0|[1-9]\d*",
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        family=lambda w: cost_probe_family(w.knob),
        corpus=lambda w: CORPORA[cost_probe_family(w.knob)["corpus"]],
        settings={k: v for k, v in PROBES.items() if k not in ("families", "seeds")},
        probe_seed=PROBES["seeds"][0],
    script:
        "../workflow/scripts/cost_probe.py"


rule cost_probe_points:
    """Points of a probe knob: Monte Carlo spread across replicate seeds, and seconds."""
    input:
        rows=cost_probe_files("results/cost/probes/{knob}/{value}/rep~{rep}.parquet"),
        benchmarks=cost_probe_files(
            "results/benchmarks/cost_probe/{knob}/{value}/{rep}.tsv"
        ),
        code=imports_of("cost_probe_points"),
    output:
        points=COST_POINTS,
    log:
        "results/logs/cost_probe_points/{knob}.log",
    benchmark:
        "results/benchmarks/cost_probe_points/{knob}.tsv"
    wildcard_constraints:
        knob=one_of(PROBE_KNOBS),
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        cells=lambda w: cost_probe_cells(w.knob),
        default=lambda w: str(
            DEFAULT_CONFIG["probes"][
                "bootstrap" if w.knob == "probe_bootstrap" else "permutations"
            ]
        ),
    script:
        "../workflow/scripts/cost_probe_points.py"


# ------------------------------------------------------------------ generator knobs


rule cost_generate_points:
    """Points of a generator knob from the generation summary and the sampling benchmarks."""
    input:
        summary="results/generate/summary.parquet",
        benchmarks=lambda w: [path for _, path in cost_generate_bench(w.knob)],
        code=imports_of("cost_generate_points"),
    output:
        points=COST_POINTS,
    log:
        "results/logs/cost_generate_points/{knob}.log",
    benchmark:
        "results/benchmarks/cost_generate_points/{knob}.tsv"
    wildcard_constraints:
        knob=one_of(GENERATE_KNOBS),
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        corpus=lambda w: cost_generate(w.knob)[0],
        target=lambda w: cost_generate(w.knob)[1],
        guidance=lambda w: cost_generate(w.knob)[2],
        default=lambda w: cost_generate(w.knob)[3],
        cells=lambda w: cost_generate(w.knob)[4],
        bench_cells=lambda w: [cell for cell, _ in cost_generate_bench(w.knob)],
    script:
        "../workflow/scripts/cost_generate_points.py"


# ------------------------------------------------------------------ policy knobs


rule cost_policy_points:
    """Points of a policy knob from the policy summary and the training and rollout benchmarks."""
    input:
        summary=f"{POLICY_DIR}/summary.parquet",
        benchmarks=lambda w: [path for _, path in cost_policy_bench(w.knob)],
        code=imports_of("cost_policy_points"),
    output:
        points=COST_POINTS,
    log:
        "results/logs/cost_policy_points/{knob}.log",
    benchmark:
        "results/benchmarks/cost_policy_points/{knob}.tsv"
    wildcard_constraints:
        knob=one_of(POLICY_KNOBS),
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        default=lambda w: cost_policy(w.knob)[0],
        cells=lambda w: cost_policy(w.knob)[1],
        bench_cells=lambda w: [cell for cell, _ in cost_policy_bench(w.knob)],
    script:
        "../workflow/scripts/cost_policy_points.py"


# ------------------------------------------------------------------ the page


localrules:
    cost_of_accuracy,


rule cost_of_accuracy:
    """The cost page: per knob, metric ± uncertainty against seconds, default, Pareto front."""
    input:
        points=cost_points,
        code=imports_of("cost_of_accuracy"),
    output:
        html=report(
            "results/report/cost_of_accuracy.html",
            caption="../workflow/report/cost_of_accuracy.rst",
            category=category("Cost of accuracy"),
            labels={"table": "knobs: what each setting buys"},
        ),
        marginal=report(
            "results/report/cost_marginal.html",
            caption="../workflow/report/cost_marginal.rst",
            category=category("Cost of accuracy"),
            labels={"table": "marginal accuracy per extra minute"},
        ),
        figure=report(
            directory("results/report/cost_of_accuracy"),
            patterns=["{knob}.png"],
            caption="../workflow/report/cost_of_accuracy_figure.rst",
            category=category("Cost of accuracy"),
            subcategory="Figures",
            labels={"knob": "{knob}"},
        ),
        tsv="results/report/cost_of_accuracy.tsv",
    log:
        "results/logs/cost_of_accuracy.log",
    benchmark:
        "results/benchmarks/cost_of_accuracy.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        stages=COST_KNOBS,
        swept=sorted(COST_KNOB_CONFIG),
    script:
        "../workflow/scripts/cost_of_accuracy.py"
