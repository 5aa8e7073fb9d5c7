"""Policy stage: does touch make a grasp-lift-hold policy succeed where vision cannot?

Oracle demonstrations and held-out episodes are simulated in shards (collect_demos: palpation
frames rendered once per episode); palpate turns their frames into frozen-backbone and aligned
features; train_policy fits one behaviour-cloning MLP per condition x H x E x seed (demos only,
guarded); rollout_policy lifts every held-out episode with each policy's grip force (physics
only, sharded); policy_regression probes the required grip force; aggregate_policy writes the
summary, the paired deltas and the report's Policy section (tacgen_lib.policy).
"""


include: "policy_common.smk"


if POLICY_ON:
    TARGETS += expand(
        "{d}/{name}.parquet", d=POLICY_DIR, name=["summary", "deltas", "regression"]
    )
    TARGETS += expand("{d}/{t}.html", d=POLICY_REPORT, t=POLICY_TABLES)
    TARGETS += expand("{d}/{f}.png", d=POLICY_REPORT, f=POLICY_FIGURES)
    EDGES += PLANS.policy.episodes() + [f"{POLICY_DIR}/palpation.parquet"]
    EDGES += PLANS.policy.rollouts()
    EDGES += expand(
        "{d}/{name}.parquet",
        d=POLICY_DIR,
        name=["summary", "deltas", "regression", "sweep", "failures"],
    )


localrules:
    aggregate_policy,


rule collect_demos:
    """One shard of oracle demonstrations or held-out episodes: objects, palpation frames, oracle."""
    input:
        scenes=config["scenes_file"],
        code=imports_of("collect_demos"),
    output:
        f"{POLICY_DIR}/episodes/{{episode_set}}/shard~{{shard}}.parquet",
    log:
        "results/logs/collect_demos/{episode_set}/{shard}.log",
    benchmark:
        "results/benchmarks/collect_demos/{episode_set}/{shard}.tsv"
    wildcard_constraints:
        episode_set="demos|heldout",
    conda:
        "../envs/policy.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        settings=POLICY,
    script:
        "../workflow/scripts/collect_demos.py"


rule palpate:
    """Frozen V and T features of every episode's palpation, and T projected by the press corpus's heads."""
    input:
        episodes=PLANS.policy.episodes(),
        vision="results/features/backbones/vision.pt",
        tactile="results/features/backbones/tactile.pt",
        heads=list(PLANS.policy.heads().values()),
        code=imports_of("palpate"),
    output:
        f"{POLICY_DIR}/palpation.parquet",
    log:
        "results/logs/palpate.log",
    benchmark:
        "results/benchmarks/palpate.tsv"
    priority: CHAIN_PRIORITY
    conda:
        "../envs/policy.yaml"
    threads: config["features"]["threads"]  # frozen-backbone features, as extraction
    resources:
        mem_mb=3000,
        runtime=20,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=POLICY,
        features=config["features"],
        align_seeds=list(PLANS.policy.heads()),
    script:
        "../workflow/scripts/palpate.py"


rule train_policy:
    """Behaviour cloning of the oracle's grip force from one condition's features (demos only)."""
    input:
        palpation=f"{POLICY_DIR}/palpation.parquet",
        code=imports_of("train_policy"),
    output:
        weights=f"{POLICY_DIR}/policies/{POLICY_CELL_PATTERN}/policy.pt",
        curve=f"{POLICY_DIR}/policies/{POLICY_CELL_PATTERN}/curve.parquet",
    log:
        f"results/logs/train_policy/{POLICY_CELL_PATTERN}.log",
    benchmark:
        f"results/benchmarks/train_policy/{POLICY_CELL_PATTERN}.tsv"
    wildcard_constraints:
        **{**POLICY_CELL_CONSTRAINTS, "condition": "v|vt_aligned|vt_raw|vt_null"},
    priority: CHAIN_PRIORITY
    conda:
        "../envs/policy.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=20,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=POLICY,
    script:
        "../workflow/scripts/train_policy.py"


rule rollout_policy:
    """Physics-only lifts of one shard of held-out episodes with one policy's grip forces."""
    input:
        episodes=PLANS.policy.episodes("heldout"),
        palpation=f"{POLICY_DIR}/palpation.parquet",
        scenes=config["scenes_file"],
        weights=PLANS.policy.weights,
        code=imports_of("rollout_policy"),
    output:
        f"{POLICY_DIR}/rollouts/{POLICY_CELL_PATTERN}/shard~{{shard}}.parquet",
    log:
        f"results/logs/rollout_policy/{POLICY_CELL_PATTERN}/{{shard}}.log",
    benchmark:
        f"results/benchmarks/rollout_policy/{POLICY_CELL_PATTERN}/{{shard}}.tsv"
    wildcard_constraints:
        **POLICY_CELL_CONSTRAINTS,
    priority: CHAIN_PRIORITY
    conda:
        "../envs/policy.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        device=DEVICE,  # config device (tacgen_lib.runtime.device)
        settings=POLICY,
    script:
        "../workflow/scripts/rollout_policy.py"


rule policy_regression:
    """Ridge probes V vs V+T-aligned -> the grip force an object needs, per alignment seed."""
    input:
        palpation=f"{POLICY_DIR}/palpation.parquet",
        code=imports_of("policy_regression"),
    output:
        f"{POLICY_DIR}/regression.parquet",
    log:
        "results/logs/policy_regression.log",
    benchmark:
        "results/benchmarks/policy_regression.tsv"
    conda:
        "../envs/policy.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        settings=POLICY,
        align_seeds=list(PLANS.policy.heads()),
    script:
        "../workflow/scripts/policy_regression.py"


rule aggregate_policy:
    """Success with CIs per cell, paired Δ against V, failure modes, the sweep; the Policy report."""
    input:
        rollouts=PLANS.policy.rollouts(),
        benchmarks=PLANS.policy.rollouts(
            "results/benchmarks/rollout_policy/{cell}/{k}.tsv"
        ),
        train_benchmarks=PLANS.policy.train_benchmarks(),
        collect=[
            p.replace(f"{POLICY_DIR}/episodes/", "results/benchmarks/collect_demos/")
            .replace("shard~", "")
            .replace(".parquet", ".tsv")
            for p in PLANS.policy.episodes()
        ],
        heldout=PLANS.policy.episodes("heldout"),
        regression=f"{POLICY_DIR}/regression.parquet",
        code=imports_of("aggregate_policy"),
    output:
        summary=f"{POLICY_DIR}/summary.parquet",
        deltas=f"{POLICY_DIR}/deltas.parquet",
        sweep=f"{POLICY_DIR}/sweep.parquet",
        failures=f"{POLICY_DIR}/failures.parquet",
        success=report(
            f"{POLICY_REPORT}/success.html",
            caption="../workflow/report/policy_success.rst",
            category=category("Policy"),
            subcategory="Success",
            labels={"table": "success and Δ vs V"},
        ),
        sweep_table=report(
            f"{POLICY_REPORT}/sweep.html",
            caption="../workflow/report/policy_sweep.rst",
            category=category("Policy"),
            subcategory="Capacity sweep",
            labels={"table": "V-only capacity sweep"},
        ),
        regression_table=report(
            f"{POLICY_REPORT}/regression.html",
            caption="../workflow/report/policy_regression.rst",
            category=category("Policy"),
            subcategory="Grip-force regression",
            labels={"table": "grip-force regression"},
        ),
        sweep_figure=report(
            f"{POLICY_REPORT}/sweep.png",
            caption="../workflow/report/policy_sweep.rst",
            category=category("Policy"),
            subcategory="Capacity sweep",
            labels={"figure": "V-only success against width, with the ceiling"},
        ),
        failures_figure=report(
            f"{POLICY_REPORT}/failures.png",
            caption="../workflow/report/policy_failures.rst",
            category=category("Policy"),
            subcategory="Success",
            labels={"figure": "failure modes"},
        ),
        filmstrip=report(
            f"{POLICY_REPORT}/filmstrip.png",
            caption="../workflow/report/policy_filmstrip.rst",
            category=category("Policy"),
            subcategory="Episodes",
            labels={"figure": "filmstrip"},
        ),
        cost=report(
            f"{POLICY_REPORT}/cost.html",
            caption="../workflow/report/policy_cost.rst",
            category=category("Cost of accuracy"),
            subcategory="Policy rollouts",
            labels={"table": "policy rollout cost"},
        ),
    log:
        "results/logs/aggregate_policy.log",
    benchmark:
        "results/benchmarks/aggregate_policy.tsv"
    priority: CHAIN_PRIORITY
    conda:
        "../envs/report.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        settings=POLICY,
        cells=POLICY_CELLS,
    script:
        "../workflow/scripts/aggregate_policy.py"
