"""Helpers of the align stage (grid expansion, canonical cell paths); included by align.smk.

`aligned_edge(...)` is the entry point other stages (probes) use to ask for aligned projections.
"""

from tacgen_lib.align.cell_names import (
    CELL_CONSTRAINTS,
    CELL_PATTERN,
    cell_name,
    tau_text,
)

ALIGN = config["align"]
ALIGN_CORPORA = ALIGN["corpora"]
#: corpora whose heads may be trained: the grid's, and the transfer corpus (its heads, at the
#: probes' heads cell, are the transfer stage's upper reference)
HEADS_CORPORA = ALIGN_CORPORA + (
    [TRANSFER_CORPUS]
    if TRANSFER_CORPUS and TRANSFER_CORPUS not in ALIGN_CORPORA
    else []
)
ALIGN_REPORT = "results/report/align"
ALIGN_CELL = f"results/align/{CELL_PATTERN}"


def align_cells():
    """Names of every grid cell, in the order `align_grid` expands them."""
    return align_grid(CELL_PATTERN)


def align_grid(path):
    """`path` expanded over every grid cell of config align (corpora x variants x seeds x taus x N)."""
    return expand(
        path,
        corpus=ALIGN_CORPORA,
        variant=ALIGN["variants"],
        seed=ALIGN["seeds"],
        tau=[tau_text(t) for t in ALIGN["taus"]],
        n_train=[str(n) for n in ALIGN["n_train"]],
    )


def aligned_edge(heads_from, target, variant, seed, tau, n_train):
    """Aligned projections of corpus `target` by the heads trained on `heads_from` (one cell)."""
    if heads_from not in HEADS_CORPORA:
        raise ValueError(
            f"aligned_edge: heads_from={heads_from!r} is not in align.corpora {ALIGN_CORPORA}; "
            "add it there so its heads are trained"
        )
    cell = cell_name(heads_from, variant, seed, tau, n_train)
    return f"results/align/{cell}/aligned~{target}.parquet"


def _align_ref_n():
    """Training size of the τ table and the curve figure: 'all' if in the grid, else the largest."""
    ns = [str(n) for n in ALIGN["n_train"]]
    return "all" if "all" in ns else max(ns, key=int)


def _align_ref_tau():
    """τ of the N-scaling table: the probes' heads τ if in the grid, else the first τ."""
    taus = [tau_text(t) for t in ALIGN["taus"]]
    want = tau_text(config["probes"]["heads"]["tau"])
    return want if want in taus else taus[0]
