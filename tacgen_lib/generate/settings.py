"""The generate stage's settings: one frozen object from config ``generate`` (one per stage, read by `io.config.settings_from`).

`GenerateSettings.from_config(config["generate"])` reads what training, sampling and evaluating
the generator need (the schema, config/config.schema.yaml, has already checked types); the grid
itself (corpora, seeds, guidance, samplers x steps) is expanded by the rules into wildcards.
`GenerateSettings.tiny()` is a seconds-long budget for tests.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

from tacgen_lib.io.config import settings_from

__all__ = ["GenerateSettings", "SAMPLERS", "check_gamma_multiples", "check_grid"]

#: The samplers of the grid: DDPM ancestral (over all T steps) and DDIM (any number of steps).
SAMPLERS = ("ddim", "ddpm")


def check_gamma_multiples(gammas: tuple[float, ...], key: str) -> None:
    """Refuse an empty grid of RBF gamma multiples (of the median heuristic), or one with a
    multiple <= 0; `key` names the config key in the error."""
    if not gammas or any(g <= 0 for g in gammas):
        raise ValueError(f"{key} must be positive numbers, got {gammas!r}")


@dataclass(frozen=True)
class GenerateSettings:
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

    schedule: Literal["cosine", "linear"] = "cosine"
    train_steps: int = 1000
    prediction: Literal["eps", "v"] = "eps"
    hidden: int = 256
    blocks: int = 2
    time_dim: int = 128
    p_uncond: float = 0.1
    lr: float = 2e-3
    weight_decay: float = 0.01
    batch_size: int = 128
    steps: int = 500
    clip_grad: float = 1.0
    ema_decay: float = 0.99
    eval_every: int = 100
    patience: int = 3
    eta: float = 0.0
    batch: int = 2048
    permutations: int = 1000
    nonlinear_gammas: tuple[float, ...] = (0.25, 1.0, 4.0)
    cv_repeats: int = 10

    def __post_init__(self) -> None:
        if self.schedule not in ("cosine", "linear"):
            raise ValueError(
                f"generate.schedule must be 'cosine' or 'linear', got {self.schedule!r}"
            )
        if self.prediction not in ("eps", "v"):
            raise ValueError(f"generate.prediction must be 'eps' or 'v', got {self.prediction!r}")
        ints = (
            ("train_steps", 2),
            ("hidden", 1),
            ("blocks", 0),
            ("time_dim", 2),
            ("batch_size", 2),
            ("steps", 1),
            ("eval_every", 1),
            ("patience", 0),
            ("batch", 1),
            ("permutations", 0),
            ("cv_repeats", 1),
        )
        for name, low in ints:
            value = getattr(self, name)
            if int(value) != value or value < low:
                raise ValueError(f"generate.{name} must be an integer >= {low}, got {value!r}")
        for name, lo, hi in (("p_uncond", 0.0, 1.0), ("ema_decay", 0.0, 1.0), ("eta", 0.0, 1.0)):
            value = getattr(self, name)
            if not (lo <= value <= hi):
                raise ValueError(f"generate.{name} must be in [{lo}, {hi}], got {value!r}")
        for name in ("lr", "weight_decay", "clip_grad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"generate.{name} must be a finite number >= 0, got {value!r}")
        check_gamma_multiples(self.nonlinear_gammas, "generate.nonlinear_gammas")

    @classmethod
    def from_config(cls, generate: Mapping[str, Any]) -> GenerateSettings:
        """Settings from config ``generate`` (its grid keys are the rules': they expand them)."""
        return settings_from(
            cls,
            generate,
            where="generate",
            ignore=("corpora", "guidance", "samplers", "seeds", "variant"),
        )

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
