"""Helpers of the policy stage (cells, episode shards, heads, rollouts); included by policy.smk."""

from tacgen_lib.align.cell_names import cell_name as align_cell_name
from tacgen_lib.policy.policy_cells import (
    CELL_CONSTRAINTS as POLICY_CELL_CONSTRAINTS,
    CELL_PATTERN as POLICY_CELL_PATTERN,
    all_cells,
    cell_name as policy_cell_name,
)
from tacgen_lib.policy.settings import PolicySettings

POLICY = config["policy"]
POLICY_SETTINGS = PolicySettings.from_config(POLICY)
POLICY_DIR = "results/policy"
POLICY_REPORT = "results/report/policy"
POLICY_CELLS = [policy_cell_name(c) for c in all_cells(POLICY_SETTINGS)]
POLICY_SHARDS = {
    "demos": POLICY_SETTINGS.collect_shards,
    "heldout": POLICY_SETTINGS.collect_shards,
}
POLICY_TABLES = ["success", "sweep", "regression"]
POLICY_FIGURES = ["sweep", "failures", "filmstrip"]

# The stage needs the heads of a simulated paired corpus: a config without that corpus (for
# example real data only, --replace-workflow-config) leaves the policy stage out of `all`.
POLICY_ON = POLICY_SETTINGS.heads_from in CORPORA
if POLICY_ON and POLICY_SETTINGS.heads_from not in ALIGN_CORPORA:
    raise ValueError(
        f"config policy.heads_from: {POLICY_SETTINGS.heads_from!r} is not in align.corpora "
        f"{ALIGN_CORPORA}; the palpation features need its alignment heads"
    )
if POLICY_ON and POLICY_SETTINGS.heads_seed not in ALIGN["seeds"]:
    raise ValueError(
        f"config policy.heads_seed: {POLICY_SETTINGS.heads_seed} is not in align.seeds {ALIGN['seeds']}"
    )


def policy_episodes(episode_set=None):
    sets = [episode_set] if episode_set else sorted(POLICY_SHARDS)
    return [
        f"{POLICY_DIR}/episodes/{s}/shard~{k}.parquet"
        for s in sets
        for k in range(POLICY_SHARDS[s])
    ]


def policy_heads():
    """The alignment heads of every alignment seed (the BC uses heads_seed's)."""
    s = POLICY_SETTINGS
    cells = {
        seed: align_cell_name(
            s.heads_from, s.heads_variant, seed, s.heads_tau, s.heads_n_train
        )
        for seed in ALIGN["seeds"]
    }
    return {str(seed): f"results/align/{cell}/heads.pt" for seed, cell in cells.items()}


def policy_rollouts(pattern="{d}/rollouts/{cell}/shard~{k}.parquet"):
    return [
        pattern.format(d=POLICY_DIR, cell=c, k=k)
        for c in POLICY_CELLS
        for k in range(POLICY_SETTINGS.rollout_shards)
    ]


def policy_train_benchmarks():
    """The benchmark files of every learned cell's training job (the references train none)."""
    return [
        f"results/benchmarks/train_policy/{policy_cell_name(c)}.tsv"
        for c in all_cells(POLICY_SETTINGS)
        if c[0] not in ("oracle", "vision_ceiling")
    ]


def policy_weights(wildcards):
    if wildcards.condition in ("oracle", "vision_ceiling"):
        return []
    return [f"{POLICY_DIR}/policies/{POLICY_CELL_PATTERN}/policy.pt"]
