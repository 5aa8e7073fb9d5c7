"""Tactile-to-language evidence (tacgen_lib.language.adapter): per generator corpus, captions
from ground truth, an offline text encoder and a tactile adapter fitted on train rows, and
forced choices of real, generated and shuffled generated touch on the test rows."""

LANGUAGE = config["language"]
LANGUAGE_CORPORA = GENERATE_CORPORA if LANGUAGE["enabled"] else []
LANGUAGE_EDGE = "results/language/{corpus}/evidence.parquet"
_REF = (
    PLANS.generate.reference_cell()
)  # (sampler, guidance, steps): the T_gen the adapter reads
LANGUAGE_CELL = (
    f"generator seed {GENERATE['seeds'][0]}, {_REF[0]} {_REF[2]} steps, w = {_REF[1]}"
)

if LANGUAGE_CORPORA:
    TARGETS += ["results/report/language/table.html"]
    EDGES += ["results/language/evidence.parquet"]
    EDGES += [LANGUAGE_EDGE.format(corpus=c) for c in LANGUAGE_CORPORA]


rule language_evidence:
    """Captions, text encoder and tactile adapter on one corpus's train rows; forced choices of real, generated and shuffled generated touch on its test rows."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        t=lambda w: PLANS.generate.tactile(w.corpus),
        t_gen=lambda w: sample_edge(
            w.corpus, GENERATE["seeds"][0], *PLANS.generate.reference_cell()
        ),
        code=imports_of("language_evidence"),
    output:
        rows=LANGUAGE_EDGE,
    log:
        "results/logs/language_evidence/{corpus}.log",
    benchmark:
        "results/benchmarks/language_evidence/{corpus}.tsv"
    wildcard_constraints:
        corpus=one_of(LANGUAGE_CORPORA),
    conda:
        "../envs/probes.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        bootstrap=config["probes"]["bootstrap"],
        seed=config["probes"]["seeds"][0],
    script:
        "../workflow/scripts/language_evidence.py"


rule aggregate_language:
    """Every corpus's language evidence; the report page Touch to language."""
    input:
        rows=[LANGUAGE_EDGE.format(corpus=c) for c in LANGUAGE_CORPORA],
        code=imports_of("aggregate_language"),
    output:
        table=report(
            "results/report/language/table.html",
            caption="../workflow/report/language_table.rst",
            category=category("Touch to language"),
            labels={"item": "forced choices"},
        ),
        evidence="results/language/evidence.parquet",
    log:
        "results/logs/aggregate_language.log",
    benchmark:
        "results/benchmarks/aggregate_language.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        cell=LANGUAGE_CELL,
    script:
        "../workflow/scripts/aggregate_language.py"
