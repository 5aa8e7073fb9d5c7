"""Preprocess stage: tactile background subtraction, the canonical clip128 and its ablations."""

VARIANTS = config["preprocess"]["variants"]


rule background_subtract:
    """tactile_proc = clip(tactile − background + 128) with each sensor's own background, or an ablation."""
    input:
        samples=corpus_edge("{corpus}"),
        sensors=corpus_edge("{corpus}", "sensors"),
        code=imports_of("background_subtract"),
    output:
        "results/preprocess/{corpus}/{variant}.parquet",
    log:
        "results/logs/background_subtract/{corpus}/{variant}.log",
    benchmark:
        "results/benchmarks/background_subtract/{corpus}/{variant}.tsv"
    wildcard_constraints:
        variant=one_of(VARIANTS),
    conda:
        "../envs/features.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    script:
        "../workflow/scripts/background_subtract.py"
