"""Transfer to a second sensor (tacgen_lib.probes.transfer): the mass-quantile class of unseen
objects pressed by a GelSight-like sensor, V vs V+T with heads from the first sensor's corpus,
heads retrained on the second (upper reference) and heads from the null corpus (floor).
"""


include: "transfer_common.smk"


rule transfer_evaluate:
    """Mass-quantile probes on the transfer corpus's unseen objects: V vs V+T per heads view, heads seed and probe seed, object-bootstrap CIs, the shuffled-touch control; the page."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        v=feature_edge(TRANSFER_CORPUS, "vision"),
        t=feature_edge(TRANSFER_CORPUS, "tactile", config["probes"]["heads"]["variant"]),
        aligned=[
            PLANS.transfer.aligned(v, s)
            for s in ALIGN["seeds"]
            for v in TRANSFER_VIEWS
        ],
        code=imports_of("transfer_evaluate"),
    output:
        summary="results/transfer/summary.parquet",
        table=report(
            f"{TRANSFER_REPORT}/table.html",
            caption="../workflow/report/transfer_table.rst",
            category=category("Transfer to a second sensor"),
            labels={"item": "balanced accuracy per heads view"},
        ),
        figure=report(
            f"{TRANSFER_REPORT}/delta.png",
            caption="../workflow/report/transfer_delta.rst",
            category=category("Transfer to a second sensor"),
            labels={"item": "Δ per probe seed"},
        ),
    log:
        "results/logs/transfer_evaluate.log",
    benchmark:
        "results/benchmarks/transfer_evaluate.tsv"
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        settings=TRANSFER,
        corpus=TRANSFER_CORPUS,
        views=TRANSFER_VIEWS,
        heads_seeds=ALIGN["seeds"],
    script:
        "../workflow/scripts/transfer_evaluate.py"
