"""Cost of accuracy: every knob's metric with its uncertainty against the seconds it costs, and
the page.

`snakemake --cores 2 cost_of_accuracy --configfile config/cost.yaml` runs every knob listed in
config cost.knobs around the run's own settings: each setting is the main workflow again with
the knob's config keys changed (a module per setting, rules/cost_common.smk). The default run
draws the page from the knobs its own grids already vary (the backbone families, generator
steps and samplers, the policy sweep), through the same rule.
"""


include: "cost_common.smk"


wildcard_constraints:
    knob="[a-z][a-z0-9_]*",


# ------------------------------------------------------------------ every knob


rule cost_knob_points:
    """Points of a knob: what each setting's edges show (a swept knob's main-rule edges, a free
    knob's stage summary), against the seconds of its jobs' benchmark files."""
    input:
        unpack(COST_PLAN.knob_inputs),
        code=imports_of("cost_knob_points"),
    output:
        points=COST_POINTS,
    log:
        "results/logs/cost_knob_points/{knob}.log",
    benchmark:
        "results/benchmarks/cost_knob_points/{knob}.tsv"
    wildcard_constraints:
        knob=one_of(COST_PLAN.knobs()),
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        plan=lambda w: COST_PLAN.setting_plan(w.knob),
        reads=lambda w: KNOBS[w.knob].reads,
        options=lambda w: COST_PLAN.knob_options(w.knob),
    script:
        "../workflow/scripts/cost_knob_points.py"


# ------------------------------------------------------------------ the page


localrules:
    cost_of_accuracy,


rule cost_of_accuracy:
    """The cost page: per knob, metric ± uncertainty against seconds, default, Pareto front."""
    input:
        points=COST_PLAN.points,
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
        stages={k: KNOBS[k].stage for k in COST_PLAN.knobs()},
        swept=sorted(COST_PLAN.knob_config),
    script:
        "../workflow/scripts/cost_of_accuracy.py"
