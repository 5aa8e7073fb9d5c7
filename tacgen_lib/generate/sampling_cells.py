"""Names of the generate stage's grid cells and paths: one source of truth for rules and readers.

A generator is one corpus x seed (`GENERATOR`); a sampling cell adds sampler, guidance w and
steps (`SAMPLE_CELL`). Guidance is written canonically (`guidance_text`: 1.0 -> "1", 0.50 ->
"0.5"), so one value has one path.
"""

from __future__ import annotations

__all__ = [
    "BASELINES",
    "RIDGE_INPUTS",
    "family_size",
    "GENERATOR",
    "SAMPLE_CELL",
    "SAMPLE_CONSTRAINTS",
    "cell_seed",
    "generator_cells",
    "guidance_passes",
    "guidance_text",
    "sample_cells",
]

#: Directory of one generator (train_generator's outputs, evaluate_generator's outputs).
GENERATOR = "results/generate/{corpus}/seed~{seed}"
#: The probes of one corpus that no generator changes (fit_generator_baselines's edge).
BASELINES = "results/generate/{corpus}/baselines.parquet"
#: Directory of one sampling cell of a generator.
SAMPLE_CELL = GENERATOR + "/sampler~{sampler}/guidance~{guidance}/steps~{steps}"
#: What the ridge V->T generator's two arms add to V in an evaluation row
#: (`tacgen_lib.generate.ridge_generator`): its conditional mean, and the mean plus a sampled residual.
RIDGE_INPUTS = ("t_ridge", "t_ridge_residual")
#: Wildcard constraints that keep cell text canonical.
SAMPLE_CONSTRAINTS = {
    "seed": r"0|[1-9]\d*",
    "sampler": "ddim|ddpm",
    "guidance": r"(0|[1-9]\d*)(\.\d*[1-9])?",
    "steps": r"[1-9]\d*",
}


def guidance_text(w: float | str) -> str:
    """Canonical text of a guidance scale (no trailing zeros): 1.0 -> "1", 1.50 -> "1.5"."""
    value = float(w)
    if value < 0:
        raise ValueError(f"guidance must be >= 0, got {w!r}")
    return f"{value:g}"


def guidance_passes(guidance: float | str) -> tuple[bool, ...]:
    """The ``drop`` flag of each network pass eps^ = eps_u + w (eps_c - eps_u) needs at w:
    (False, True) (conditional, unconditional) in general; (False,) at w = 1, where
    eps^ = eps_c, and (True,) at w = 0, where eps^ = eps_u. Sampling runs these passes
    (`sampling.project_guidance`); the run-time estimate counts them."""
    w = float(guidance)
    if w == 1.0:
        return (False,)
    if w == 0.0:
        return (True,)
    return (False, True)


def sample_cells(guidance: list, samplers: dict) -> list[tuple[str, str, str]]:
    """Every (sampler, guidance text, steps text) of config ``generate``, in config order."""
    return [
        (sampler, guidance_text(w), str(int(s)))
        for sampler, steps in samplers.items()
        for s in steps
        for w in guidance
    ]


def generator_cells(path: str, cells: list[tuple[str, str, str]]) -> list[str]:
    """`path` (a pattern of SAMPLE_CELL's fields) for each (sampler, guidance, steps) of
    `cells`, its `{corpus}` and `{seed}` left as wildcards: the outputs of one generator's
    sampling job, in the order of `cells`."""
    return [
        path.format(corpus="{corpus}", seed="{seed}", sampler=s, guidance=g, steps=n)
        for s, g, n in cells
    ]


def cell_seed(generator_seed: int | str, guidance: float | str, steps: int | str) -> int:
    """The sampling noise's seed of one cell of a generator: the generator seed, the steps and
    the guidance (in thousandths), so each cell is reproducible on its own, whichever job or
    worker samples it."""
    return int(generator_seed) * 1_000_003 + int(steps) * 101 + int(round(float(guidance) * 1000))


def family_size(n_cells: int, n_seeds: int) -> int:
    """How many generated-touch rows of one corpus x target the Generation page compares (the
    family of `generate.evaluate_probes.family_interval`): V + T_gen and its shuffled control in
    each of `n_cells` sampling cells, and the ridge V->T generator's arms (`RIDGE_INPUTS`), for
    each of `n_seeds` generator seeds."""
    return int(n_seeds) * (2 * int(n_cells) + len(RIDGE_INPUTS))
