"""Where generated touch helps, and where it cannot (tacgen_lib.generate.regime): per natural
corpus (one rho each) x seed, diffusion generators trained on unlabelled paired pools of
every size (real and re-paired pairs), then every arm of the regime fitted on N_L labelled
rows and scored on the corpus's test split; one summary and the report page."""


include: "regime_common.smk"


if REGIME_CORPORA:
    TARGETS += [f"{REGIME_DIR}/summary.parquet"]
    TARGETS += [f"{REGIME_REPORT}/{n}.{e}" for n, e in REGIME_ITEMS.items()]
    EDGES += [f"{REGIME_DIR}/evaluation.parquet", f"{REGIME_DIR}/look_control.parquet"]
    EDGES += [p for c, s in PLANS.regime.cells() for p in PLANS.regime.t_gen(c, s)]


rule regime_generators:
    """Latent V->T diffusion generators on the unlabelled pools of one corpus x seed (real and re-paired pairs), sampled for its labelled and test rows."""
    input:
        v=lambda w: feature_edge(w.corpus, "vision"),
        t=lambda w: PLANS.generate.tactile(w.corpus),
        splits="results/corpus/splits.parquet",
        code=imports_of("regime_generators"),
    output:
        t_gen=PLANS.regime.t_gen("{corpus}", "{seed}"),
        curves=f"{REGIME_CELL}/curves.parquet",
    log:
        "results/logs/regime_generators/{corpus}/{seed}.log",
    benchmark:
        "results/benchmarks/regime_generators/{corpus}/{seed}.tsv"
    wildcard_constraints:
        corpus=one_of(REGIME_CORPORA),
        seed=r"\d+",
    conda:
        "../envs/generate.yaml"
    threads: 2  # its generators in forked one-thread workers (runtime.workers)
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        generate=GENERATE,
        regime=REGIME,
        cells=REGIME_CELLS,  # the order of the t_gen outputs
    script:
        "../workflow/scripts/regime_generators.py"


rule regime_evaluate:
    """Every arm of the regime (linear and nonlinear V, the generator ladder from the look oracle to one diffusion sample, the shuffled-pool generator, generalised distillation, V + real T, the V ceiling and the vision ceiling) for one corpus x seed."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        v=lambda w: feature_edge(w.corpus, "vision"),
        t=lambda w: PLANS.generate.tactile(w.corpus),
        t_gen=lambda w: PLANS.regime.t_gen(w.corpus, w.seed),
        code=imports_of("regime_evaluate"),
    output:
        rows=f"{REGIME_CELL}/evaluation.parquet",
    log:
        "results/logs/regime_evaluate/{corpus}/{seed}.log",
    benchmark:
        "results/benchmarks/regime_evaluate/{corpus}/{seed}.tsv"
    wildcard_constraints:
        corpus=one_of(REGIME_CORPORA),
        seed=r"\d+",
    conda:
        "../envs/probes.yaml"
    threads: 2  # its (target, N_L) cells in forked one-thread workers (runtime.workers)
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        regime=REGIME,
        targets=REGIME["targets"],
        rho=lambda w: float(CORPORA[w.corpus]["rho"]),
        probes=PROBE_SETTINGS,
        probe_seed=config["probes"]["seeds"][0],
        gammas=GENERATE["nonlinear_gammas"],
        ceiling=VISIBILITY,  # the V ceiling's kernel probe is the visibility check's
        cells=REGIME_CELLS,
        look_control_snr=None,  # real touch (regime_look_control: the positive control's)
    script:
        "../workflow/scripts/regime_evaluate.py"


rule regime_look_control:
    """The curve's positive control for one corpus x seed (tacgen_lib.generate.look_control): every arm but the diffusion generator's, on touch that is the look's mean real touch plus noise at config regime.look_control_snr."""
    input:
        manifest="results/corpus/manifest.parquet",
        splits="results/corpus/splits.parquet",
        v=lambda w: feature_edge(w.corpus, "vision"),
        t=lambda w: PLANS.generate.tactile(w.corpus),
        code=imports_of("regime_evaluate"),
    output:
        rows=REGIME_CONTROL,
    log:
        "results/logs/regime_look_control/{corpus}/{seed}.log",
    benchmark:
        "results/benchmarks/regime_look_control/{corpus}/{seed}.tsv"
    wildcard_constraints:
        corpus=one_of(REGIME_CONTROL_CORPORA),
        seed=r"\d+",
    conda:
        "../envs/probes.yaml"
    threads: 2  # its (target, N_L) cells in forked one-thread workers (runtime.workers)
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        regime=REGIME,
        targets=REGIME["targets"],
        rho=lambda w: float(CORPORA[w.corpus]["rho"]),
        probes=PROBE_SETTINGS,
        probe_seed=config["probes"]["seeds"][0],
        gammas=GENERATE["nonlinear_gammas"],
        cells=REGIME_CELLS,  # only their pool sizes: no generator is read
        look_control_snr=REGIME["look_control_snr"],
    script:
        "../workflow/scripts/regime_evaluate.py"


rule aggregate_regime:
    """One summary of every regime cell and arm; the report page Where generated touch helps."""
    input:
        rows=PLANS.regime.files(f"{REGIME_CELL}/evaluation.parquet"),
        visibility=VISIBILITY_EDGE,
        curves=PLANS.regime.files(f"{REGIME_CELL}/curves.parquet"),
        control=PLANS.regime.control_files(REGIME_CONTROL),
        code=imports_of("aggregate_regime"),
    output:
        **{
            name: report(
                f"{REGIME_REPORT}/{name}.{ext}",
                caption=f"../workflow/report/regime_{name}.rst",
                category=category("Where generated touch helps"),
                subcategory="Figures" if ext == "png" else "Tables",
                labels={"item": name},
            )
            for name, ext in REGIME_ITEMS.items()
        },
        summary=f"{REGIME_DIR}/summary.parquet",
        evaluation=f"{REGIME_DIR}/evaluation.parquet",
        control=f"{REGIME_DIR}/look_control.parquet",
    log:
        "results/logs/aggregate_regime.log",
    benchmark:
        "results/benchmarks/aggregate_regime.tsv"
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        gate=VISIBILITY["gate"],  # the visibility gate of the regime's corpora
        look_control_snr=REGIME["look_control_snr"],  # the positive control's, as it ran
    script:
        "../workflow/scripts/aggregate_regime.py"
