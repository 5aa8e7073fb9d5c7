"""Probe robustness: the headline Deltas under protocol variants, training sizes and splits.

This module owns the settings of the robustness runs (config ``probes.robustness``,
`RobustnessSettings`) and the two analyses that are not a protocol variant:

- `training_size_sweep`: the headline comparison (raw V vs V+T, ``concat``,
  heads' tactile variant) refitted on nested subsets of the training rows, n in a configured
  grid, for several subset seeds; each point has its fixed-test bootstrap CI on the full test
  rows. Subsets are nested (a smaller n is a prefix of a larger one for the same seed) and,
  for class targets, stratified at every prefix (`subsets.nested_subsets`).
- the held-out-scale diagnosis (`protocol.family_rows` with ``within_scale``,
  `subsets.within_scale_split`). The appearance-controlled corpus is split
  by scale (train 0.15/0.20, test 0.25), so its mass probe extrapolates to an unseen scale.
  This re-splits the TRAINING rows only (train + val; the held-out test rows are never used)
  at random within each scale, so a probe on it asks "does touch carry mass" without asking
  "does the fit extrapolate to a new scale". The two results sit side by side in the report.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from tacgen_lib.probes.mlp import MLPGrid
from tacgen_lib.probes.protocol import FamilyRows, ProbeSettings, compare
from tacgen_lib.probes.subsets import nested_subsets
from tacgen_lib.probes.variants import PROTOCOLS, same_as_raw

__all__ = ["SIZE_COLUMNS", "RobustnessSettings", "training_size_sweep"]


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
        size, within, mlp = cfg["training_size"], cfg["within_scale"], cfg["mlp"]
        out = cls(
            protocols=tuple(cfg["protocols"]),
            families=tuple(cfg["families"]),
            comparisons=str(cfg["comparisons"]),
            controls=bool(cfg["controls"]),
            mlp=MLPGrid(
                widths=tuple(int(w) for w in mlp["widths"]),
                weight_decays=tuple(float(a) for a in mlp["weight_decays"]),
                folds=int(mlp["folds"]),
                max_iter=int(mlp["max_iter"]),
            ),
            size_families=tuple(size["families"]),
            size_n_train=tuple(n if n == "all" else int(n) for n in size["n_train"]),
            size_seeds=tuple(int(s) for s in size["seeds"]),
            within_families=tuple(within["families"]),
            within_test_fraction=float(within["test_fraction"]),
            within_seed=int(within["seed"]),
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


# --------------------------------------------------------------------------- subsets


def _subset(rows: FamilyRows, idx: np.ndarray) -> FamilyRows:
    vis = None if rows.visible_train is None else rows.visible_train[idx]
    return replace(
        rows, train_ids=rows.train_ids[idx], y_train=rows.y_train[idx], visible_train=vis
    )


#: Columns of the training-size edge (one row per family, subset seed and n).
SIZE_COLUMNS = (
    "row_id", "family", "corpus", "target", "metric", "protocol", "subset_seed", "n_requested",
    "n_train", "n_test", "status", "v_score", "vt_score", "delta", "ci_low", "ci_high",
    "p_gt0", "n_resamples", "notes",
)  # fmt: skip


def training_size_sweep(
    family: str,
    rows: FamilyRows,
    *,
    vision: tuple[np.ndarray, np.ndarray],
    tactile: tuple[np.ndarray, np.ndarray],
    settings: ProbeSettings,
    sizes: Sequence[int | str],
    seeds: Sequence[int],
    progress: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """Raw V vs V+T (concat) at every training size and subset seed; one row per point.

    The subset seed also seeds the CV folds and the bootstrap of that point, so the spread
    over seeds includes them. Test rows are the family's full test split at every point.
    A point whose probe cannot be fitted (a class left with one row) is a ``failed`` row.
    """
    say = progress or (lambda _m: None)
    labels = rows.y_train if settings.kind == "logistic" else None
    out = []
    for seed in seeds:
        for size, idx in nested_subsets(rows.n_train, sizes, seed, labels=labels).items():
            sub = _subset(rows, idx)
            s = replace(settings, seed=int(seed))
            key = f"{family}|n~{size}|s~{seed}"
            base = {
                "row_id": key, "family": family, "corpus": rows.corpus, "target": rows.target,
                "metric": settings.metric, "protocol": settings.protocol,
                "subset_seed": int(seed), "n_requested": str(size), "n_train": int(idx.size),
                "n_test": rows.n_test,
            }  # fmt: skip
            try:
                res = compare(
                    vision[0][idx], vision[1], tactile[0][idx], tactile[1], sub, "concat", s,
                    controls=False,
                )  # fmt: skip
            except ValueError as exc:
                out.append(
                    {**base, "status": "failed", "notes": f"probe could not be fitted: {exc}"}
                )
                say(f"{key}: failed ({exc})")
                continue
            m = res.main
            out.append(
                {**base, "status": "ok", **{c: m[c] for c in (
                    "v_score", "vt_score", "delta", "ci_low", "ci_high", "p_gt0", "n_resamples")},
                 "notes": ""}
            )  # fmt: skip
            say(f"{key}: delta {m['delta']:+.3f} [{m['ci_low']:+.3f}, {m['ci_high']:+.3f}]")
    frame = pd.DataFrame(out, columns=list(SIZE_COLUMNS))
    frame["notes"] = frame["notes"].fillna("").astype(str)
    for col in ("v_score", "vt_score", "delta", "ci_low", "ci_high", "p_gt0"):
        frame[col] = frame[col].astype(np.float64)
    frame["n_resamples"] = pd.array(
        [None if pd.isna(v) else int(v) for v in frame["n_resamples"]], dtype="Int64"
    )
    return frame
