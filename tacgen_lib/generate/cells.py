"""Names of the generate stage's grid cells and paths: one source of truth for rules and readers.

A generator is one corpus x seed (`GENERATOR`); a sampling cell adds sampler, guidance w and
steps (`SAMPLE_CELL`). Guidance is written canonically (`guidance_text`: 1.0 -> "1", 0.50 ->
"0.5"), so one value has one path.
"""

from __future__ import annotations

__all__ = [
    "BASELINES",
    "GENERATOR",
    "SAMPLE_CELL",
    "SAMPLE_CONSTRAINTS",
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
