"""The generate stage's settings: one frozen object from config ``generate`` (one per stage, read by `io.config.settings_from`).

`GenerateSettings.from_config(config["generate"])` reads what training, sampling and evaluating
the generator need (its fields, their types, defaults and bounds are the keys of ``generate`` in
config/config.schema.yaml, `io.schema.schema_fields`); the grid itself (corpora, seeds,
guidance, samplers x steps) is expanded by the rules into wildcards.
`GenerateSettings.tiny()` is a seconds-long budget for tests.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from tacgen_lib.io.schema import SchemaSettings, schema_fields

__all__ = ["GenerateSettings", "SAMPLERS", "check_grid", "generate_grids"]

#: The samplers of the grid: DDPM ancestral (over all T steps) and DDIM (any number of steps).
SAMPLERS = ("ddim", "ddpm")


@dataclass(frozen=True)
@schema_fields("generate", skip=("corpora", "variant", "seeds", "guidance", "samplers"))
class GenerateSettings(SchemaSettings):
    """How one generator is trained (`train.fit_generator`), sampled and evaluated.

    Model: ``blocks`` residual blocks of width ``hidden`` (paper: 8 x 2048), eps- or
    v-``prediction``, a ``schedule`` (cosine | linear) of ``train_steps`` = T steps, condition
    dropped with probability ``p_uncond`` (paper 0.10) for classifier-free guidance.
    Training: AdamW (``lr``, ``weight_decay``), ``batch_size``, at most ``steps`` optimiser
    steps, gradient norm clipped at ``clip_grad``, EMA of the weights with ``ema_decay`` (the
    EMA weights are evaluated and sampled), validation loss every ``eval_every`` steps with
    early stopping after ``patience`` evaluations without improvement (0: never stop).
    Sampling: DDIM's ``eta`` (0 = deterministic); ``batch`` rows per sampling batch.
    Evaluation: ``permutations`` of the pairing-permutation check, ``nonlinear_gammas``
    (multiples of the median-heuristic RBF gamma) for the nonlinear V-only baseline,
    ``cv_repeats`` draws of the CV folds that choose every evaluation probe's regulariser
    (repeated K-fold: on a few hundred rows one draw's choice of the logistic C moved a
    verdict).
    """

    @classmethod
    def tiny(cls, **changes: Any) -> GenerateSettings:
        """A model and budget that train in about a second, for tests; `changes` override."""
        small = cls(
            hidden=32,
            blocks=1,
            time_dim=16,
            batch_size=16,
            steps=60,
            eval_every=20,
            patience=0,
            permutations=50,
            train_steps=100,
        )
        return replace(small, **changes)


def check_grid(samplers: Mapping[str, Any], train_steps: int) -> None:
    """Refuse a sampler grid the samplers cannot run (config ``generate.samplers``).

    DDPM ancestral sampling runs over all T steps, so its only steps value is T; DDIM steps
    must lie in 1..T.
    """
    for name, steps in samplers.items():
        if name not in SAMPLERS:
            raise ValueError(f"generate.samplers: unknown sampler {name!r}; choose from {SAMPLERS}")
        for s in steps:
            if name == "ddpm" and int(s) != train_steps:
                raise ValueError(
                    f"generate.samplers.ddpm: steps {s} but DDPM ancestral sampling runs all "
                    f"T = generate.train_steps = {train_steps} steps; use [{train_steps}]"
                )
            if not 1 <= int(s) <= train_steps:
                raise ValueError(
                    f"generate.samplers.{name}: steps {s} outside 1..T = {train_steps}"
                )


def baseline_targets(config: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Per corpus, the targets (target -> probe kind) of the probes no generator changes
    (rule fit_generator_baselines): the latent generator's corpora (config ``generate``) and
    the pixel generators' judged ones (config ``pixel``, an optional section), merged."""
    targets = {c: dict(t) for c, t in config["generate"]["corpora"].items()}
    pixel = config["pixel"]["corpora"] if "pixel" in config else {}
    for corpus, more in pixel.items():
        targets[corpus] = {**targets.get(corpus, {}), **more}
    return targets


def generate_grids(generate: Any) -> dict[str, list[float]]:
    """The C and lambda grids of the probes that judge generated touch, from config
    ``generate`` (a mapping with the schema's defaults filled): rules pass them as param
    ``grids``, and `job_target_specs` gives them to every target's probe."""
    return {
        "C": [float(c) for c in generate["C"]],
        "lambdas": [float(v) for v in generate["lambdas"]],
    }
