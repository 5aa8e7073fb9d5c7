"""Report stage: what a reader of `snakemake --report` looks at."""


localrules:
    corpus_examples,
    pretrain_curve,
    edge_manifest,
    findings,


TARGETS += ["results/report/edge_manifest.html"]
if PRETRAINED:
    TARGETS += expand("results/report/features/{m}_pretrain_curve.png", m=MODALITIES)
TARGETS += expand("results/report/corpus/{corpus}_examples.png", corpus=sorted(CORPORA))


rule corpus_examples:
    """Example grid per corpus (RGB, raw tactile, background, subtracted), label distributions, force bands vs true force."""
    input:
        samples=corpus_edge("{corpus}"),
        sensors=corpus_edge("{corpus}", "sensors"),
        splits="results/corpus/splits.parquet",
        code=imports_of("corpus_examples"),
    output:
        examples=report(
            "results/report/corpus/{corpus}_examples.png",
            caption="../workflow/report/corpus_examples.rst",
            category=category("Preprocessing"),
            labels={
                "corpus": "{corpus}",
                "figure": "RGB, tactile, background, subtracted",
            },
        ),
        labels=report(
            "results/report/corpus/{corpus}_labels.png",
            caption="../workflow/report/corpus_labels.rst",
            category=category("Corpus"),
            labels={"corpus": "{corpus}", "figure": "label distributions"},
        ),
        force_bands=report(
            "results/report/corpus/{corpus}_force_bands.html",
            caption="../workflow/report/corpus_force_bands.rst",
            category=category("Corpus"),
            labels={
                "corpus": "{corpus}",
                "figure": "force bands against the true force",
            },
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


rule pretrain_curve:
    """A backbone's DINO pretraining curve, drawn apart from the training job."""
    input:
        curve="results/features/backbones/{modality}_curve.parquet",
        code=imports_of("pretrain_curve"),
    output:
        figure=features_report_item(
            "results/report/features/{modality}_pretrain_curve.png",
            "../workflow/report/pretrain_curve.rst",
            {"modality": "{modality}", "figure": "pretraining curve"},
            FEATURES_SHOWN,
        ),
    log:
        "results/logs/pretrain_curve/{modality}.log",
    benchmark:
        "results/benchmarks/pretrain_curve/{modality}.tsv"
    wildcard_constraints:
        modality="vision|tactile",
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        arch=lambda w: FEATURES["backbones"][w.modality]["arch"],
        objective=lambda w: FEATURES["backbones"][w.modality]["objective"],
    script:
        "../workflow/scripts/pretrain_curve.py"


rule edge_manifest:
    """Every edge of the run with its SHA-256, rows, columns and producing rule, re-verified."""
    input:
        edges=lambda w: sorted(set(EDGES)),
        code=imports_of("edge_manifest"),
    output:
        html=report(
            "results/report/edge_manifest.html",
            caption="../workflow/report/edge_manifest.rst",
            category=category("Provenance"),
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


TARGETS += ["results/report/findings.html"]


rule findings:
    """The findings page: headline results with their controls and generated verdicts."""
    input:
        **findings_inputs(
            policy=POLICY_ON,
            regime=bool(REGIME_CORPORA),
            visibility=bool(SIM_CORPORA),
            backbones=PLANS.families.on_findings,
            transfer=bool(TRANSFER_CORPUS),
            pixel=bool(PIXEL_CORPORA),
        ),
        probes="results/probes/summary.parquet",
        generation="results/generate/evaluation.parquet",
        code=imports_of("findings"),
    output:
        html=report(
            "results/report/findings.html",
            caption="../workflow/report/findings.rst",
            category=category("Findings"),
            labels={"table": "headline results, controls and verdicts"},
        ),
        # one row per decision the page states (tacgen_lib.report.decisions): what two runs
        # are compared by (tools/device_check.py --compare)
        decisions=str(DECISIONS),
    log:
        "results/logs/findings.log",
    benchmark:
        "results/benchmarks/findings.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        run_name=config["run_name"],
        generate_ref=PLANS.generate.reference(),
        policy=POLICY_ON,
        regime=bool(REGIME_CORPORA),
        regime_corpora=REGIME_CORPORA,
        look_control_snr=REGIME["look_control_snr"] if REGIME else None,
        visibility=bool(SIM_CORPORA),
        gate=VISIBILITY["gate"],
        transfer=bool(TRANSFER_CORPUS),
        pixel=bool(PIXEL_CORPORA),
        backbones=(
            {"main": PLANS.families.main, "order": list(PLANS.families.settings.run)}
            if PLANS.families.on_findings
            else {}
        ),
    script:
        "../workflow/scripts/findings.py"
