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
from dataclasses import dataclass, replace

from tacgen_lib.io.config import settings_from
from tacgen_lib.io.schema import SchemaSettings, check_settings, not_config, schema_fields, setting
from tacgen_lib.probes.protocol_variants import check_protocol, same_as_raw

__all__ = [
    "ALIGNED_VISION",
    "MLPGrid",
    "ProbeFamily",
    "RobustnessSettings",
    "check_families",
    "has_aligned_rows",
]


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
@schema_fields("probes.families.*")
class ProbeFamily(SchemaSettings):
    """One probe family (config ``probes.families.<name>``): a `kind` probe (ridge | logistic)
    of manifest column `target` on `corpus`'s rows, V from its `vision` features (pixel | vit),
    its aligned rows from the heads trained on corpus `heads_from`."""

    name: str = not_config()  # the family's name (its key under probes.families)

    @classmethod
    def from_config(cls, name: str, spec: Mapping) -> ProbeFamily:
        """Family `name` from its declaration ``probes.families.<name>``."""
        return settings_from(cls, spec, where=f"probes.families.{name}", name=name)


@dataclass(frozen=True)
@schema_fields("probes.robustness.mlp")
class MLPGrid(SchemaSettings):
    """The 2-layer probe's CV grid and solver budget (config ``probes.robustness.mlp``)."""

    @property
    def points(self) -> list[tuple[float, int]]:
        """(weight decay, width) grid points in CV order (GridSearchCV's: alpha outermost)."""
        return list(itertools.product(self.weight_decays, self.widths))


@dataclass(frozen=True)
class RobustnessSettings:
    """Config ``probes.robustness``: which families run under which protocol variants, how
    much of each, the training-size sweep and the within-scale diagnosis."""

    protocols: tuple[str, ...] = setting("probes.robustness.protocols")
    families: tuple[str, ...] = setting("probes.robustness.families")
    # "headline" | "all" comparisons, and controls or not, under a non-raw protocol
    comparisons: str = setting("probes.robustness.comparisons")
    controls: bool = setting("probes.robustness.controls")
    mlp: MLPGrid = setting("probes.robustness.mlp", default_factory=MLPGrid)
    size_families: tuple[str, ...] = setting("probes.robustness.training_size.families")
    size_n_train: tuple[int | str, ...] = setting("probes.robustness.training_size.n_train")
    size_seeds: tuple[int, ...] = setting("probes.robustness.training_size.seeds")
    within_families: tuple[str, ...] = setting("probes.robustness.within_scale.families")
    within_test_fraction: float = setting("probes.robustness.within_scale.test_fraction")
    within_seed: int = setting("probes.robustness.within_scale.seed")

    def __post_init__(self) -> None:
        check_settings(self)

    @classmethod
    def from_config(cls, cfg: Mapping, declared_families: Mapping[str, Mapping] | None = None):
        """From ``probes.robustness``; `declared_families` (``probes.families``), where given,
        checks the names."""
        # the two nested sections are read as dotted keys (the fields' `setting` keys)
        nested = ("training_size", "within_scale")
        flat = {k: v for k, v in cfg.items() if k not in ("mlp", *nested)}
        flat |= {f"{n}.{k}": v for n in nested for k, v in (cfg.get(n) or {}).items()}
        out = settings_from(
            cls, flat, where="probes.robustness", mlp=MLPGrid.from_config(cfg.get("mlp"))
        )
        if declared_families is not None:
            for key, names in (
                ("families", out.families),
                ("training_size.families", out.size_families),
                ("within_scale.families", out.within_families),
            ):
                unknown = [n for n in names if n not in declared_families]
                if unknown:
                    raise ValueError(
                        f"probes.robustness.{key}: {unknown} not in probes.families "
                        f"({', '.join(sorted(declared_families))})"
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
        for `families` where it differs from raw (`protocol_variants.same_as_raw`)."""
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

    kind: str = not_config()  # "ridge" | "logistic": the family's
    lambdas: tuple[float, ...] = setting("probes.lambdas")
    C: tuple[float, ...] = setting("probes.C")
    folds: int = setting("probes.folds")
    bootstrap: int = setting("probes.bootstrap")
    train_resamples: int = setting("probes.train_resamples")
    permutations: int = setting("probes.permutations")
    label_permutations: int = setting("probes.label_permutations")
    random_draws: int = setting("probes.random_draws")
    seed: int = not_config()  # the probe seed (a grid value of probes.seeds)
    #: the smallest gain the comparisons call meaningful (the paper's, not a config key)
    min_delta: float = not_config(0.03)
    protocol: str = not_config("raw")  # a name of `protocol_variants.PROTOCOLS`
    #: seed of the bootstrap resamples and control draws; None: `seed` (which also draws the
    #: CV folds). The cost sweep's probe knobs vary it alone to measure Monte Carlo error.
    resample_seed: int | None = setting("probes.resample_seed")
    #: draws of the CV folds whose mean held-out score chooses the regulariser (repeated K-fold)
    cv_repeats: int = setting("probes.cv_repeats")
    #: the ``mlp2`` probe's grid
    mlp: MLPGrid = setting("probes.robustness.mlp", default_factory=MLPGrid)

    def __post_init__(self) -> None:
        if self.kind not in ("ridge", "logistic"):
            raise ValueError(f"ProbeSettings.kind must be 'ridge' or 'logistic', got {self.kind!r}")
        check_protocol(self.protocol)
        check_settings(self)

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
