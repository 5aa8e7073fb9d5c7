"""Corpus stage: simulate (or ingest) corpora, fuse their manifest, fix the splits."""

from tacgen_lib.generate.regime_sets import natural_grid_ends

for _c in config["splits"]["by_object"]:
    if _c not in CORPORA:
        raise ValueError(
            f"config splits.by_object: {_c!r} is not a corpus (have {sorted(CORPORA)})"
        )
    if CORPORA[_c]["kind"] != "simulated" or CORPORA[_c]["contacts"] < 2:
        raise ValueError(
            f"config splits.by_object: corpus {_c!r} has one contact per object "
            f"(corpora.{_c}.contacts); split it by fractions instead"
        )


localrules:
    fuse_manifest,
    make_splits,


# the regime's natural corpora (one per rho) differ only in what their objects look like: one
# job per shard simulates their physics and touch once (simulate_natural_grid)
NATURAL_GRID = PLANS.features.natural_grid
# and a corpus between the grid's ends (rho 0 and 1) looks as one of them in every sample: it
# shares their vision features (share_natural_vision)
NATURAL_ENDS, NATURAL_BETWEEN = natural_grid_ends(config.get("regime"))


rule simulate_corpus:
    """One shard of a MuJoCo-simulated corpus: only the effects its scene declares are computed."""
    input:
        scenes=config["scenes_file"],
        code=imports_of("simulate_corpus"),
    output:
        temp("results/corpus/{corpus}/shards/{shard}.parquet"),
    log:
        "results/logs/simulate_corpus/{corpus}/{shard}.log",
    benchmark:
        "results/benchmarks/simulate_corpus/{corpus}/{shard}.tsv"
    wildcard_constraints:
        corpus=one_of([c for c in SIM_CORPORA if c not in NATURAL_GRID]),
    conda:
        "../envs/corpus.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        corpora=lambda w: [{"name": w.corpus, **CORPORA[w.corpus]}],
        n_shards=lambda w: CORPORA[w.corpus]["shards"],
    script:
        "../workflow/scripts/simulate_corpus.py"


if NATURAL_GRID:

    rule simulate_natural_grid:
        """One shard of every natural corpus of the regime's rho grid: each sample's physics and touch simulated once (they do not depend on rho), its RGB frame rendered for each corpus."""
        input:
            scenes=config["scenes_file"],
            code=imports_of("simulate_corpus"),
        output:
            [temp(f"results/corpus/{c}/shards/{{shard}}.parquet") for c in NATURAL_GRID],
        log:
            "results/logs/simulate_natural_grid/{shard}.log",
        benchmark:
            "results/benchmarks/simulate_natural_grid/{shard}.tsv"
        wildcard_constraints:
            shard=r"\d+",
        conda:
            "../envs/corpus.yaml"
        threads: 1
        resources:
            mem_mb=2000,
            runtime=30,
        params:
            corpora=[{"name": c, **CORPORA[c]} for c in NATURAL_GRID],
            n_shards=CORPORA[NATURAL_GRID[0]]["shards"],
        script:
            "../workflow/scripts/simulate_corpus.py"


rule merge_corpus:
    """Concatenate a simulated corpus's shards and record each sensor's background image."""
    input:
        shards=lambda w: expand(
            "results/corpus/{corpus}/shards/{shard}.parquet",
            corpus=w.corpus,
            shard=range(CORPORA[w.corpus]["shards"]),
        ),
        scenes=config["scenes_file"],
        code=imports_of("merge_corpus"),
    output:
        samples="results/corpus/{corpus}/samples.parquet",
        sensors="results/corpus/{corpus}/sensors.parquet",
    log:
        "results/logs/merge_corpus/{corpus}.log",
    benchmark:
        "results/benchmarks/merge_corpus/{corpus}.tsv"
    wildcard_constraints:
        corpus=one_of(SIM_CORPORA),
    conda:
        "../envs/corpus.yaml"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=10,
    params:
        corpus=lambda w: {"name": w.corpus, **CORPORA[w.corpus]},
    script:
        "../workflow/scripts/merge_corpus.py"


rule ingest_tvl:
    """A real TVL corpus from its published folder (SSVTP or HCT, read as the authors' loaders read it) into the corpus edge schema, streamed one row group of images at a time."""
    input:
        root=lambda w: CORPORA[w.corpus]["root"],
        code=imports_of("ingest_tvl"),
    output:
        samples="results/corpus/{corpus}/samples.parquet",
        sensors="results/corpus/{corpus}/sensors.parquet",
    log:
        "results/logs/ingest_tvl/{corpus}.log",
    benchmark:
        "results/benchmarks/ingest_tvl/{corpus}.tsv"
    wildcard_constraints:
        corpus=one_of(REAL_CORPORA),
    conda:
        "../envs/corpus.yaml"
    threads: 1
    # memory: one row group of images (tacgen_lib.corpus.ingest.ROW_GROUP_BYTES of PNG) and the
    # plan's text, whatever the corpus's size (benchmarks/bench_ingest.py measures it); the
    # runtime is the estimate's (its units: the rows the dataset's split CSVs list)
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        corpus=lambda w: {"name": w.corpus, **CORPORA[w.corpus]},
    script:
        "../workflow/scripts/ingest_tvl.py"


rule fuse_manifest:
    """One manifest pool keyed by sample_id across every corpus (labels, captions, no pixels)."""
    input:
        samples=expand(corpus_edge("{corpus}"), corpus=sorted(CORPORA)),
        code=imports_of("fuse_manifest"),
    output:
        "results/corpus/manifest.parquet",
    log:
        "results/logs/fuse_manifest.log",
    benchmark:
        "results/benchmarks/fuse_manifest.tsv"
    conda:
        "../envs/corpus.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=5,
    script:
        "../workflow/scripts/fuse_manifest.py"


rule make_splits:
    """Fixed train/val/test splits, stratified at a fixed seed, made before any feature exists."""
    input:
        manifest="results/corpus/manifest.parquet",
        code=imports_of("make_splits"),
    output:
        "results/corpus/splits.parquet",
    log:
        "results/logs/make_splits.log",
    benchmark:
        "results/benchmarks/make_splits.tsv"
    conda:
        "../envs/corpus.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        splits=config["splits"],
    script:
        "../workflow/scripts/make_splits.py"
