"""Cost of accuracy: every knob's metric with its uncertainty against the seconds it costs, and
the page.

`snakemake --cores 2 cost_of_accuracy --configfile config/cost.yaml` runs every knob listed in
config cost.knobs around the run's own settings: each setting is the main workflow again with
the knob's config keys changed (a module per setting, rules/cost_common.smk). The default run
draws the page from the knobs its own grids already vary (generator steps and samplers, the
policy sweep).
"""


include: "cost_common.smk"
include: "cost_sweep_common.smk"


wildcard_constraints:
    knob="[a-z][a-z0-9_]*",


# ------------------------------------------------------------------ swept knobs


rule cost_knob_points:
    """Points of a swept knob: what each setting's main-rule edges show, against the seconds
    of its jobs' benchmark files."""
    input:
        unpack(cost_knob_inputs),
        code=imports_of("cost_knob_points"),
    output:
        points=COST_POINTS,
    log:
        "results/logs/cost_knob_points/{knob}.log",
    benchmark:
        "results/benchmarks/cost_knob_points/{knob}.tsv"
    wildcard_constraints:
        knob=one_of(SWEPT_KNOBS),
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        plan=lambda w: cost_setting_plan(w.knob),
        reads=lambda w: KNOBS[w.knob].reads,
        options=lambda w: cost_knob_options(w.knob),
    script:
        "../workflow/scripts/cost_knob_points.py"


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
        knob=one_of([k for k in FREE_KNOBS if KNOBS[k].stage == "generate"]),
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


# ------------------------------------------------------------------ backbone families


rule cost_backbone_points:
    """Points of the backbone-family knob from the families' summary and the benchmarks of the jobs that make each family's backbones and features."""
    input:
        summary="results/backbones/summary.parquet",
        benchmarks=[path for _, path in cost_backbone_bench()],
        code=imports_of("cost_backbone_points"),
    output:
        points=COST_POINTS,
    log:
        "results/logs/cost_backbone_points/{knob}.log",
    benchmark:
        "results/benchmarks/cost_backbone_points/{knob}.tsv"
    wildcard_constraints:
        knob=one_of([k for k in FREE_KNOBS if KNOBS[k].stage == "features"]),
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        order=list(FAMILIES.run),
        default=(MAIN_FAMILIES or [None])[0],
        bench_families=[family for family, _ in cost_backbone_bench()],
    script:
        "../workflow/scripts/cost_backbone_points.py"


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
        knob=one_of([k for k in FREE_KNOBS if KNOBS[k].stage == "policy"]),
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
        stages={k: KNOBS[k].stage for k in cost_knobs()},
        swept=sorted(COST_KNOB_CONFIG),
    script:
        "../workflow/scripts/cost_of_accuracy.py"
