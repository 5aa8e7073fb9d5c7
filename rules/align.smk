"""Align stage: symmetric InfoNCE heads per grid cell (paper eq. 1), retrieval, summary."""


include: "align_common.smk"


TARGETS += PLANS.align.grid(f"{ALIGN_CELL}/metrics.parquet")
TARGETS += ["results/align/summary.parquet"]
TARGETS += expand(
    f"{ALIGN_REPORT}/{{item}}",
    item=["tau_ablation.html", "n_scaling.html", "seeds.html", "curves.png"],
)
EDGES += ["results/align/metrics.parquet"]
for _name in ("metrics.parquet", "ranks.parquet", "curve.parquet", "heads.pt"):
    EDGES += PLANS.align.grid(f"{ALIGN_CELL}/{_name}")


localrules:
    aggregate_align,


rule train_heads:
    """Symmetric InfoNCE heads on frozen V and T features of one corpus's train split, early-stopped on val."""
    input:
        v=lambda w: feature_edge(w.corpus, "vision"),
        t=lambda w: feature_edge(w.corpus, "tactile", w.variant),
        splits="results/corpus/splits.parquet",
        code=imports_of("train_heads"),
    output:
        heads=f"{ALIGN_CELL}/heads.pt",
        metrics=f"{ALIGN_CELL}/metrics.parquet",
        ranks=f"{ALIGN_CELL}/ranks.parquet",
        curve=f"{ALIGN_CELL}/curve.parquet",
    log:
        f"results/logs/train_heads/{CELL_PATTERN}.log",
    benchmark:
        f"results/benchmarks/train_heads/{CELL_PATTERN}.tsv"
    wildcard_constraints:
        **CELL_CONSTRAINTS,
        corpus=one_of(HEADS_CORPORA),
        variant=one_of(ALIGN["variants"]),
    priority: CHAIN_PRIORITY
    conda:
        "../envs/align.yaml"
    # one thread, so two cells train side by side: at the default's sizes a second thread
    # shortens a cell little and costs more CPU than it saves (benchmarks/bench_align.py with
    # --threads 1 and --threads 2 measures both); profiles/slurm gives 2.
    # Reruns are bit-identical per thread count.
    threads: 1
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=ALIGN,  # the whole subtree; tacgen_lib.align.settings reads it
    script:
        "../workflow/scripts/train_heads.py"


rule project_aligned:
    """Aligned 128-d projections of every sample of {target} by the heads trained on {corpus}."""
    input:
        heads=f"{ALIGN_CELL}/heads.pt",
        v=lambda w: feature_edge(w.target, "vision"),
        t=lambda w: feature_edge(w.target, "tactile", w.variant),
        code=imports_of("project_aligned"),
    output:
        f"{ALIGN_CELL}/aligned~{{target}}.parquet",
    log:
        f"results/logs/project_aligned/{CELL_PATTERN}/{{target}}.log",
    benchmark:
        f"results/benchmarks/project_aligned/{CELL_PATTERN}/{{target}}.tsv"
    wildcard_constraints:
        **CELL_CONSTRAINTS,
        corpus=one_of(HEADS_CORPORA),
        variant=one_of(ALIGN["variants"]),
        target=one_of(sorted(CORPORA)),
    conda:
        "../envs/align.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=ALIGN,
    script:
        "../workflow/scripts/project_aligned.py"


rule aggregate_align:
    """One row per grid cell with its train time (benchmark), and the τ, N and seed tables and curves."""
    input:
        metrics=PLANS.align.grid(f"{ALIGN_CELL}/metrics.parquet"),
        curves=PLANS.align.grid(f"{ALIGN_CELL}/curve.parquet"),
        benchmarks=PLANS.align.grid(
            f"results/benchmarks/train_heads/{CELL_PATTERN}.tsv"
        ),
        code=imports_of("aggregate_align"),
    output:
        summary="results/align/summary.parquet",
        metrics="results/align/metrics.parquet",
        tau=report(
            f"{ALIGN_REPORT}/tau_ablation.html",
            caption="../workflow/report/align_tau.rst",
            category=category("Alignment"),
            subcategory="Retrieval",
            labels={"table": "τ ablation"},
        ),
        n_scaling=report(
            f"{ALIGN_REPORT}/n_scaling.html",
            caption="../workflow/report/align_n_scaling.rst",
            category=category("Alignment"),
            subcategory="Retrieval",
            labels={"table": "N scaling"},
        ),
        seeds=report(
            f"{ALIGN_REPORT}/seeds.html",
            caption="../workflow/report/align_seeds.rst",
            category=category("Alignment"),
            subcategory="Retrieval",
            labels={"table": "retrieval over seeds"},
        ),
        curves=report(
            f"{ALIGN_REPORT}/curves.png",
            caption="../workflow/report/align_curves.rst",
            category=category("Alignment"),
            subcategory="Training",
            labels={"figure": "training curves"},
        ),
    log:
        "results/logs/aggregate_align.log",
    benchmark:
        "results/benchmarks/aggregate_align.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        cells=PLANS.align.cells(),  # the order of the metrics, curves and benchmarks inputs
        n_ref=PLANS.align.reference_n(),
        tau_ref=PLANS.align.reference_tau(),
    script:
        "../workflow/scripts/aggregate_align.py"
