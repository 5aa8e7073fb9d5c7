"""Settings of the probes stage that the Snakefile reads when it is parsed: the families'
checks (`check_families`, `has_aligned_rows`), the 2-layer probe's grid (`MLPGrid`) and the
robustness runs' settings (`RobustnessSettings`, config ``probes.robustness``).

Standard library only (no numpy, pandas or scikit-learn): every Snakemake start parses these,
and a cluster job parses the Snakefile again, so they must not pay for the probes' numerics
(scikit-learn and SciPy took ~0.75 s of a ~3 s dry run). The modules that fit probes
(`protocol`, `mlp`, `robustness`) import them from here.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

from tacgen_lib.io.config import settings_from
from tacgen_lib.probes.variants import PROTOCOLS, check_protocol, same_as_raw

__all__ = ["ALIGNED_VISION", "MLPGrid", "RobustnessSettings", "check_families", "has_aligned_rows"]


#: The V features the alignment heads project: only families with this V have aligned rows.
ALIGNED_VISION = "vit"


def has_aligned_rows(vision: str) -> bool:
    """Whether a family whose V is `vision` ("pixel" | "vit") gets aligned comparisons.

    The heads project ViT features, so aligned V is ViT-derived whatever the family's V; in a
    pixel-V family aligned rows would set a different V baseline than its raw rows and repeat
    the rows of the ViT family of the same target. A pixel-V family is raw rows only.
    """
    return vision == ALIGNED_VISION


def check_families(families: Mapping[str, Mapping]) -> None:
    """Refuse families whose rows would repeat another's (config ``probes.families``).

    Raw rows are set by (corpus, target, kind, V features); two families that share these
    would repeat every raw row. Aligned rows exist only for ViT-V families
    (`has_aligned_rows`), so the same key also keeps two families' aligned rows apart unless
    they differ in ``heads_from`` -- and then their raw rows would repeat, which is refused.
    """
    seen: dict[tuple, str] = {}
    for name in sorted(families):
        fam = families[name]
        key = (fam["corpus"], fam["target"], fam["kind"], fam["vision"])
        if key in seen:
            raise ValueError(
                f"probes.families: {name!r} and {seen[key]!r} would produce identical raw rows "
                f"({', '.join(map(str, key))}); drop one or change its corpus, target, kind or "
                "vision"
            )
        seen[key] = name


@dataclass(frozen=True)
class MLPGrid:
    """The 2-layer probe's CV grid and solver budget (config ``probes.robustness.mlp``)."""

    widths: tuple[int, ...] = (64,)
    weight_decays: tuple[float, ...] = (0.01, 1.0)
    folds: int = 3
    max_iter: int = 200

    @classmethod
    def from_config(cls, mlp: Mapping | None) -> MLPGrid:
        """From ``probes.robustness.mlp`` (None: the defaults)."""
        return settings_from(cls, mlp, where="probes.robustness.mlp")

    def __post_init__(self) -> None:
        if not self.widths or min(self.widths) < 1:
            raise ValueError(f"probes.robustness.mlp.widths: need widths >= 1, got {self.widths}")
        if not self.weight_decays or min(self.weight_decays) < 0:
            raise ValueError(
                f"probes.robustness.mlp.weight_decays: need values >= 0, got {self.weight_decays}"
            )
        if self.folds < 2 or self.max_iter < 1:
            raise ValueError(
                f"probes.robustness.mlp: need folds >= 2 and max_iter >= 1, got {self.folds}, "
                f"{self.max_iter}"
            )

    @property
    def points(self) -> list[tuple[float, int]]:
        """(weight decay, width) grid points in CV order (GridSearchCV's: alpha outermost)."""
        return list(itertools.product(self.weight_decays, self.widths))


@dataclass(frozen=True)
class RobustnessSettings:
    """Config ``probes.robustness``: which families run under which protocol variants, how
    much of each, the training-size sweep and the within-scale diagnosis."""

    protocols: tuple[str, ...] = ("raw", "standardised", "mlp2")
    families: tuple[str, ...] = ()
    comparisons: str = "headline"  # "headline" | "all" comparisons under a non-raw protocol
    controls: bool = False  # controls under a non-raw protocol
    mlp: MLPGrid = field(default_factory=MLPGrid)
    size_families: tuple[str, ...] = ()
    size_n_train: tuple[int | str, ...] = (50, "all")
    size_seeds: tuple[int, ...] = (42,)
    within_families: tuple[str, ...] = ()
    within_test_fraction: float = 0.33
    within_seed: int = 42

    def __post_init__(self) -> None:
        for p in self.protocols:
            if p not in PROTOCOLS:
                raise ValueError(
                    f"probes.robustness.protocols: unknown {p!r}; choose from {sorted(PROTOCOLS)}"
                )
        if "raw" not in self.protocols:
            raise ValueError("probes.robustness.protocols must include 'raw' (the reference)")
        if self.comparisons not in ("headline", "all"):
            raise ValueError(
                f"probes.robustness.comparisons must be 'headline' or 'all', got {self.comparisons!r}"
            )
        if not 0.0 < self.within_test_fraction < 1.0:
            raise ValueError(
                "probes.robustness.within_scale.test_fraction must be in (0, 1), got "
                f"{self.within_test_fraction}"
            )
        for n in self.size_n_train:
            if n != "all" and (not isinstance(n, int) or n < 2):
                raise ValueError(
                    f"probes.robustness.training_size.n_train: {n!r} is not 'all' or an int >= 2"
                )

    @classmethod
    def from_config(cls, cfg: Mapping, families: Mapping[str, Mapping] | None = None):
        """From ``probes.robustness``; `families` (``probes.families``) checks the names."""
        # the two nested sections are read as the fields' prefixed names
        flat = {k: v for k, v in cfg.items() if k not in ("mlp", "training_size", "within_scale")}
        flat |= {f"size_{k}": v for k, v in cfg["training_size"].items()}
        flat |= {f"within_{k}": v for k, v in cfg["within_scale"].items()}
        out = settings_from(
            cls, flat, where="probes.robustness", mlp=MLPGrid.from_config(cfg.get("mlp"))
        )
        if families is not None:
            for key, names in (
                ("families", out.families),
                ("training_size.families", out.size_families),
                ("within_scale.families", out.within_families),
            ):
                unknown = [n for n in names if n not in families]
                if unknown:
                    raise ValueError(
                        f"probes.robustness.{key}: {unknown} not in probes.families "
                        f"({', '.join(sorted(families))})"
                    )
        return out

    @classmethod
    def tiny(cls, **overrides) -> RobustnessSettings:
        base = cls(
            families=("fam",),
            mlp=MLPGrid(widths=(8,), weight_decays=(1.0,), folds=2, max_iter=50),
            size_families=("fam",),
            size_n_train=(10, "all"),
            size_seeds=(0, 1),
            within_families=("fam",),
        )
        return replace(base, **overrides)

    def jobs(self, families: Mapping[str, Mapping]) -> list[tuple[str, str]]:
        """(family, protocol) of every probe job: raw for every family, each other protocol
        for `families` where it differs from raw (`variants.same_as_raw`)."""
        out = [(f, "raw") for f in sorted(families)]
        for p in self.protocols:
            if p == "raw":
                continue
            out += [(f, p) for f in self.families if not same_as_raw(p, families[f]["kind"])]
        return out

    def headline_only(self, protocol: str) -> bool:
        return protocol != "raw" and self.comparisons == "headline"

    def run_controls(self, protocol: str) -> bool:
        return protocol == "raw" or self.controls


@dataclass(frozen=True)
class ProbeSettings:
    """Everything a comparison needs from config ``probes`` for one family and probe seed."""

    kind: str  # "ridge" | "logistic"
    lambdas: tuple[float, ...]
    C: tuple[float, ...]
    folds: int
    bootstrap: int
    train_resamples: int
    permutations: int
    label_permutations: int
    random_draws: int
    seed: int
    min_delta: float = 0.03
    protocol: str = "raw"  # a name of `variants.PROTOCOLS`
    #: seed of the bootstrap resamples and control draws; None: `seed` (which also draws the
    #: CV folds). The cost sweep's probe knobs vary it alone to measure Monte Carlo error.
    resample_seed: int | None = None
    #: draws of the CV folds whose mean held-out score chooses the regulariser (repeated K-fold)
    cv_repeats: int = 1
    mlp: MLPGrid = field(default_factory=MLPGrid)  # the ``mlp2`` probe's grid

    def __post_init__(self) -> None:
        if self.kind not in ("ridge", "logistic"):
            raise ValueError(f"ProbeSettings.kind must be 'ridge' or 'logistic', got {self.kind!r}")
        check_protocol(self.protocol)
        if int(self.cv_repeats) != self.cv_repeats or self.cv_repeats < 1:
            raise ValueError(f"probes.cv_repeats must be an integer >= 1, got {self.cv_repeats!r}")

    @property
    def metric(self) -> str:
        return "r2" if self.kind == "ridge" else "accuracy"

    @property
    def draw_seed(self) -> int:
        """The seed of the bootstrap resamples and the controls' draws."""
        return self.seed if self.resample_seed is None else self.resample_seed

    @property
    def reg_name(self) -> str:
        if self.protocol == "mlp2":
            return "weight_decay"
        return "lambda" if self.kind == "ridge" else "C"

    @classmethod
    def from_config(
        cls, probes_cfg: Mapping, kind: str, seed: int, protocol: str = "raw"
    ) -> ProbeSettings:
        """Settings from the config section ``probes`` (validated by the schema); the ``mlp2``
        grid from ``probes.robustness.mlp`` when present."""
        return settings_from(
            cls,
            probes_cfg,
            where="probes",
            ignore=("families", "seeds", "fusions", "heads", "robustness"),
            kind=kind,
            seed=int(seed),
            protocol=check_protocol(protocol),
            mlp=MLPGrid.from_config((probes_cfg.get("robustness") or {}).get("mlp")),
        )
