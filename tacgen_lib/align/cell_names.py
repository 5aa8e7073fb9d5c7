"""A cell of the alignment grid: its fields, its canonical name, and the paths made from it.

One source of truth for every place that names a cell (docs/alignment.md): the rules build their
output, log and benchmark paths from `CELL_PATTERN`, the training script keys its metrics row
with `cell_name`, and the aggregate reads cells back from the `cell` column of those rows,
never by parsing a path. A cell's name is the relative path of its folder below
``results/align/``: ``{corpus}/{variant}/seed~{seed}/tau~{tau}/n~{n_train}``.

Canonical text (enforced by `CELL_CONSTRAINTS` as Snakemake wildcard constraints): seeds
without leading zeros, τ as `tau_text` writes it, N an integer or ``all``.
"""

from __future__ import annotations

__all__ = [
    "CELL_COLUMNS",
    "CELL_CONSTRAINTS",
    "CELL_PATTERN",
    "cell_name",
    "tau_text",
]

CELL_COLUMNS = ("corpus", "variant", "seed", "tau", "n_train")
CELL_PATTERN = "{corpus}/{variant}/seed~{seed}/tau~{tau}/n~{n_train}"
CELL_CONSTRAINTS = {
    "seed": r"0|[1-9]\d*",
    "tau": r"(0|[1-9]\d*)\.(0|\d*[1-9])",
    "n_train": r"all|[1-9]\d*",
}


def tau_text(tau: float | str) -> str:
    """The canonical path text of a temperature: Python's shortest float repr (0.07, 0.1, 1.0)."""
    return repr(float(tau))


def cell_name(
    corpus: str, variant: str, seed: int | str, tau: float | str, n_train: int | str
) -> str:
    """The key of a grid cell: its folder below results/align/ (and its benchmark file's stem)."""
    return CELL_PATTERN.format(
        corpus=corpus, variant=variant, seed=int(seed), tau=tau_text(tau), n_train=n_train
    )
