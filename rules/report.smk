"""Report stage: what a reader of `snakemake --report` looks at."""


localrules:
    corpus_examples,
    edge_manifest,


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
