"""Report stage: what a reader of `snakemake --report` looks at."""


localrules:
    corpus_examples,
    edge_manifest,
    cost_of_accuracy,


TARGETS += ["results/report/edge_manifest.html"]
TARGETS += expand("results/report/corpus/{corpus}_examples.png", corpus=sorted(CORPORA))


rule corpus_examples:
    """Example grid per corpus: RGB, raw tactile, sensor background, background-subtracted."""
    input:
        samples=corpus_edge("{corpus}"),
        sensors=corpus_edge("{corpus}", "sensors"),
        splits="results/corpus/splits.parquet",
        code=imports_of("corpus_examples"),
    output:
        examples=report(
            "results/report/corpus/{corpus}_examples.png",
            caption="../workflow/report/corpus_examples.rst",
            category="Corpus",
            subcategory="{corpus}",
            labels={"corpus": "{corpus}", "figure": "examples"},
        ),
        labels=report(
            "results/report/corpus/{corpus}_labels.png",
            caption="../workflow/report/corpus_labels.rst",
            category="Corpus",
            subcategory="{corpus}",
            labels={"corpus": "{corpus}", "figure": "labels"},
        ),
    log:
        "results/logs/corpus_examples/{corpus}.log",
    benchmark:
        "results/benchmarks/corpus_examples/{corpus}.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=5,
    params:
        n=config["report"]["examples_per_corpus"],
    script:
        "../workflow/scripts/corpus_examples.py"


rule edge_manifest:
    """Every edge of the run with its SHA-256, rows, columns and producing rule, re-verified."""
    input:
        edges=lambda w: sorted(set(EDGES)),
        code=imports_of("edge_manifest"),
    output:
        html=report(
            "results/report/edge_manifest.html",
            caption="../workflow/report/edge_manifest.rst",
            category="Provenance",
            labels={"table": "edge manifest"},
        ),
        tsv="results/report/edge_manifest.tsv",
    log:
        "results/logs/edge_manifest.log",
    benchmark:
        "results/benchmarks/edge_manifest.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    script:
        "../workflow/scripts/edge_manifest.py"


TARGETS += ["results/report/cost_of_accuracy.html"]


rule cost_of_accuracy:
    """Each knob's accuracy against its run time: benchmark files joined with the metrics."""
    input:
        align="results/align/summary.parquet",
        pretrain="results/features/pretrained_vs_random.parquet",
        pretrain_bench=expand(
            "results/benchmarks/pretrain_backbone/{m}.tsv", m=["vision", "tactile"]
        ),
        simulate_bench=simulate_benchmarks,
        manifest="results/corpus/manifest.parquet",
        code=imports_of("cost_of_accuracy"),
    output:
        html=report(
            "results/report/cost_of_accuracy.html",
            caption="../workflow/report/cost_of_accuracy.rst",
            category="Cost of accuracy",
            labels={"table": "cost of accuracy"},
        ),
        figure=report(
            "results/report/cost_of_accuracy.png",
            caption="../workflow/report/cost_of_accuracy.rst",
            category="Cost of accuracy",
            labels={"figure": "cost of accuracy"},
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
    script:
        "../workflow/scripts/cost_of_accuracy.py"
