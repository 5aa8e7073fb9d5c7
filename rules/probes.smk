"""Probes stage: does V+T predict physical properties better than V? (paper's probe tables)

Each family in config probes.families is probed at each probe seed: V vs V+T on raw and on
aligned features, every fusion variant, the tactile preprocessing ablation, bootstrap CIs and
controls (tacgen_lib.probes.protocol). aggregate_probes joins the families into one summary and
draws the report's probe tables and figures (tacgen_lib.report.probes).
"""


include: "probes_common.smk"


TARGETS += ["results/probes/summary.parquet"]
TARGETS += expand("{d}/{t}.html", d=PROBE_REPORT, t=PROBE_TABLES)
TARGETS += expand("{d}/{f}", d=PROBE_REPORT, f=PROBE_FIGURES)  # one PNG per family
EDGES += [path for edge in PROBE_EDGES for path in PLANS.probes.job_edges(edge)]
EDGES += expand("results/probes/{t}.parquet", t=["summary", "sweep", "confusion"])


rule probe:
    """V vs V+T probes of one family, protocol variant and probe seed: CV-chosen regulariser,
    bootstrap, controls (the raw protocol; the variants as configured in probes.robustness).
    """
    input:
        unpack(PLANS.probes.inputs),
        code=imports_of("probe"),
    output:
        rows=f"{PROBE_DIR}/seed~{{seed}}.parquet",
        sweep=f"{PROBE_DIR}/sweep~{{seed}}.parquet",
        confusion=f"{PROBE_DIR}/confusion~{{seed}}.parquet",
    log:
        "results/logs/probe/{family}/protocol~{protocol}/seed~{seed}.log",
    benchmark:
        "results/benchmarks/probe/{family}/protocol~{protocol}/seed~{seed}.tsv"
    wildcard_constraints:
        family=one_of(PROBE_FAMILIES),
        protocol=one_of(PROTOCOLS),
        seed=r"0|[1-9]\d*",
    conda:
        "../envs/probes.yaml"
    threads: 1  # small dense solves: two single-threaded families beat one two-threaded one
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        family=lambda w: PROBES["families"][w.family],
        corpus=lambda w: CORPORA[PLANS.probes.family(w.family)["corpus"]],
        settings=PROBE_SETTINGS,
        fusions=PROBES["fusions"],
        heads_variant=PROBES["heads"]["variant"],
        variants=config["preprocess"]["variants"],
        align_seeds=lambda w: PLANS.probes.align_seeds(w.family),
        # the protocol variant's budget: headline comparisons only? controls?
        headline_only=lambda w: ROBUST.headline_only(w.protocol),
        controls=lambda w: ROBUST.run_controls(w.protocol),
    script:
        "../workflow/scripts/probe.py"


rule aggregate_probes:
    """One summary of every probe family and seed; the probe tables and figures of the report."""
    input:
        rows=PLANS.probes.job_edges("seed~{seed}"),
        sweep=PLANS.probes.job_edges("sweep~{seed}"),
        confusion=PLANS.probes.job_edges("confusion~{seed}"),
        code=imports_of("aggregate_probes"),
    output:
        summary="results/probes/summary.parquet",
        sweep="results/probes/sweep.parquet",
        confusion="results/probes/confusion.parquet",
        controlled=probe_report_item(
            "controlled", "html", "controlled", "controlled corpus"
        ),
        paired=probe_report_item("paired", "html", "paired", "paired corpus + null"),
        sweep_html=probe_report_item("sweep", "html", "sweep", "regulariser sweep"),
        align_seeds=probe_report_item(
            "align_seeds", "html", "align_seeds", "alignment seeds"
        ),
        variants=probe_report_item(
            "variants", "html", "variants", "preprocessing variants"
        ),
        controls=probe_report_item("controls", "html", "controls", "controls"),
        fusions=probe_report_item("fusions", "html", "fusions", "fusion variants"),
        forest=probe_report_dir("forest", "Forest plots"),
        confusion_png=probe_report_dir("confusion", "Confusion matrices"),
    log:
        "results/logs/aggregate_probes.log",
    benchmark:
        "results/benchmarks/aggregate_probes.tsv"
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    script:
        "../workflow/scripts/aggregate_probes.py"


# probe robustness: training-size sweep, within-scale split, robustness report
TARGETS += ["results/probes/robustness.parquet"]
TARGETS += expand("{d}/{t}.html", d=PROBE_REPORT, t=ROBUSTNESS_TABLES)
TARGETS += [f"{PROBE_REPORT}/training_size.png"]
EDGES += [f"results/probes/{f}/training_size.parquet" for f in ROBUST.size_families]
EDGES += [f"results/probes/{f}/within_scale.parquet" for f in ROBUST.within_families]
EDGES += expand(
    "results/probes/{t}.parquet",
    t=["robustness", "training_size", "within_scale", "multiplicity"],
)


rule probe_training_size:
    """Raw V vs V+T (concat) of one family on nested training subsets, several subset seeds."""
    input:
        unpack(PLANS.probes.raw_inputs),
        code=imports_of("probe_training_size"),
    output:
        rows="results/probes/{family}/training_size.parquet",
    log:
        "results/logs/probe_training_size/{family}.log",
    benchmark:
        "results/benchmarks/probe_training_size/{family}.tsv"
    wildcard_constraints:
        family=one_of(ROBUST.size_families or ["-"]),
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        family=lambda w: PROBES["families"][w.family],
        corpus=lambda w: CORPORA[PLANS.probes.family(w.family)["corpus"]],
        settings=PROBE_SETTINGS,
        robustness=PROBES["robustness"],
        heads_variant=PROBES["heads"]["variant"],
        variants=config["preprocess"]["variants"],
    script:
        "../workflow/scripts/probe_training_size.py"


rule probe_within_scale:
    """Held-out-scale diagnosis: one family's headline comparison on a random within-scale split
    of its training rows, under every protocol variant."""
    input:
        unpack(PLANS.probes.raw_inputs),
        code=imports_of("probe_within_scale"),
    output:
        rows="results/probes/{family}/within_scale.parquet",
    log:
        "results/logs/probe_within_scale/{family}.log",
    benchmark:
        "results/benchmarks/probe_within_scale/{family}.tsv"
    wildcard_constraints:
        family=one_of(ROBUST.within_families or ["-"]),
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        family=lambda w: PROBES["families"][w.family],
        corpus=lambda w: CORPORA[PLANS.probes.family(w.family)["corpus"]],
        settings=PROBE_SETTINGS,
        robustness=PROBES["robustness"],
        heads_variant=PROBES["heads"]["variant"],
        variants=config["preprocess"]["variants"],
    script:
        "../workflow/scripts/probe_within_scale.py"


rule aggregate_robustness:
    """Robustness of the headline probes: protocol variants, multiplicity, training sizes and
    the within-scale split, as tables and a figure of the report."""
    input:
        summary="results/probes/summary.parquet",
        training_size=[
            f"results/probes/{f}/training_size.parquet" for f in ROBUST.size_families
        ],
        within_scale=[
            f"results/probes/{f}/within_scale.parquet" for f in ROBUST.within_families
        ],
        code=imports_of("aggregate_robustness"),
    output:
        robustness="results/probes/robustness.parquet",
        training_size="results/probes/training_size.parquet",
        within_scale="results/probes/within_scale.parquet",
        multiplicity="results/probes/multiplicity.parquet",
        robustness_html=probe_report_item(
            "robustness", "html", "robustness", "protocol variants", "Robustness"
        ),
        multiplicity_html=probe_report_item(
            "multiplicity",
            "html",
            "multiplicity",
            "multiple comparisons",
            "Robustness",
        ),
        within_scale_html=probe_report_item(
            "within_scale", "html", "within_scale", "held-out scale", "Robustness"
        ),
        training_size_html=probe_report_item(
            "training_size", "html", "training_size", "training sizes", "Robustness"
        ),
        training_size_png=probe_report_item(
            "training_size",
            "png",
            "training_size",
            "training-size curves",
            "Robustness",
        ),
    log:
        "results/logs/aggregate_robustness.log",
    benchmark:
        "results/benchmarks/aggregate_robustness.tsv"
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        robustness=PROBES["robustness"],
        families=PROBES["families"],
    script:
        "../workflow/scripts/aggregate_robustness.py"
