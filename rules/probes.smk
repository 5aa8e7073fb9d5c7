"""Probes stage: does V+T predict physical properties better than V? (paper's probe tables)

Each family in config probes.families is probed at each probe seed: V vs V+T on raw and on
aligned features, every fusion variant, the tactile preprocessing ablation, bootstrap CIs and
controls (tacgen_lib.probes.protocol). aggregate_probes joins the families into one summary and
draws the report's probe tables and figures (tacgen_lib.report.probes).
"""


include: "probes_common.smk"


TARGETS += ["results/probes/summary.parquet"]
TARGETS += expand("{d}/{t}.html", d=PROBE_REPORT, t=PROBE_TABLES)
TARGETS += expand("{d}/{f}.png", d=PROBE_REPORT, f=PROBE_FIGURES)
EDGES += [
    f"results/probes/{family}/{edge.format(seed=seed)}.parquet"
    for family in PROBE_FAMILIES
    for edge in PROBE_EDGES
    for seed in PROBES["seeds"]
]
EDGES += expand("results/probes/{t}.parquet", t=["summary", "sweep", "confusion"])


rule probe:
    """V vs V+T probes of one family and probe seed: CV-chosen regulariser, bootstrap, controls."""
    input:
        unpack(probe_inputs),
        code=imports_of("probe"),
    output:
        rows=f"{PROBE_DIR}/seed~{{seed}}.parquet",
        sweep=f"{PROBE_DIR}/sweep~{{seed}}.parquet",
        confusion=f"{PROBE_DIR}/confusion~{{seed}}.parquet",
    log:
        "results/logs/probe/{family}/seed~{seed}.log",
    benchmark:
        "results/benchmarks/probe/{family}/seed~{seed}.tsv"
    wildcard_constraints:
        family=one_of(PROBE_FAMILIES),
        seed=r"0|[1-9]\d*",
    conda:
        "../envs/probes.yaml"
    threads: 1  # small dense solves: two single-threaded families beat one two-threaded one
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        family=lambda w: probe_family(w.family),
        corpus=lambda w: CORPORA[probe_family(w.family)["corpus"]],
        settings={k: v for k, v in PROBES.items() if k not in ("families", "seeds")},
        fusions=PROBES["fusions"],
        heads_variant=PROBES["heads"]["variant"],
        variants=config["preprocess"]["variants"],
        align_seeds=lambda w: probe_align_seeds(w.family),
    script:
        "../workflow/scripts/probe.py"


rule aggregate_probes:
    """One summary of every probe family and seed; the probe tables and figures of the report."""
    input:
        rows=expand(
            f"{PROBE_DIR}/seed~{{seed}}.parquet",
            family=PROBE_FAMILIES,
            seed=PROBES["seeds"],
        ),
        sweep=expand(
            f"{PROBE_DIR}/sweep~{{seed}}.parquet",
            family=PROBE_FAMILIES,
            seed=PROBES["seeds"],
        ),
        confusion=expand(
            f"{PROBE_DIR}/confusion~{{seed}}.parquet",
            family=PROBE_FAMILIES,
            seed=PROBES["seeds"],
        ),
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
        forest=probe_report_item("forest", "png", "forest", "forest plot"),
        confusion_png=probe_report_item(
            "confusion", "png", "confusion", "confusion matrices"
        ),
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
