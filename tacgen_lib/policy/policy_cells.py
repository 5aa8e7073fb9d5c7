"""Names and paths of the policy stage's grid cells: defined once, used by rules and scripts.

A cell is condition x hidden x epochs x seed. The learned conditions (settings.LEARNED_CONDITIONS)
train an MLP per cell; the references (`oracle`, `vision_ceiling`) have no MLP and use the cell
H~0/E~0/seed~0.
"""

from __future__ import annotations

from tacgen_lib.policy.settings import CONDITIONS, LEARNED_CONDITIONS, PolicySettings

__all__ = ["CELL_PATTERN", "CELL_CONSTRAINTS", "Cell", "main_cells", "sweep_cells", "all_cells"]

CELL_PATTERN = "{condition}/H~{hidden}/E~{epochs}/seed~{seed}"
CELL_CONSTRAINTS = {
    "condition": "|".join(CONDITIONS),
    "hidden": r"\d+",
    "epochs": r"\d+",
    "seed": r"\d+",
}
REFERENCES = ("oracle", "vision_ceiling")

Cell = tuple[str, int, int, int]  # condition, hidden, epochs, seed


def cell_name(cell: Cell) -> str:
    c, h, e, s = cell
    return CELL_PATTERN.format(condition=c, hidden=h, epochs=e, seed=s)


def main_cells(s: PolicySettings) -> list[Cell]:
    """Every learned condition at the matched capacity, per seed; then the two references."""
    out = [(c, s.hidden, s.epochs, seed) for seed in s.seeds for c in LEARNED_CONDITIONS]
    return out + [(r, 0, 0, 0) for r in REFERENCES]


def sweep_cells(s: PolicySettings) -> list[Cell]:
    """The V-only capacity sweep: hidden x epochs x seeds."""
    return [
        ("v", h, e, seed) for h in s.sweep_hidden for e in s.sweep_epochs for seed in s.sweep_seeds
    ]


def all_cells(s: PolicySettings) -> list[Cell]:
    """Main and sweep cells, each once, in a fixed order."""
    out: list[Cell] = []
    for c in main_cells(s) + sweep_cells(s):
        if c not in out:
            out.append(c)
    return out
