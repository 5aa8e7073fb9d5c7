"""The probes of one backbone family (`tacgen_lib.features.families`): V vs V+T (concat) of one
probe family on that family's frozen features, under the linear and the 2-layer protocol.

The paper checks that the V+T direction holds for its encoder families (DINOv2, CLIP + MAE,
Sparsh) and reports 2-layer probes beside linear ones. This is the same comparison the probes
stage makes (`compare.compare`: CV-chosen regularisation on train + val rows, a fixed-test
bootstrap CI of Delta, seeded by the probe seed so that every family and protocol sees the same
resamples), with V and T taken from the family's backbones instead of the main DAG's. The main
family's rows are those the probes stage already made (`rows_from_probes`): its headline rows,
raw V vs V+T concat on the heads' tactile variant, are this comparison on the same features.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
import pandas as pd

from tacgen_lib.probes.compare import MAIN_STATISTICS, compare, comparison_frame
from tacgen_lib.probes.rows import FamilyRows
from tacgen_lib.probes.settings import ProbeSettings

__all__ = ["FAMILY_COLUMNS", "backbone_family_rows", "rows_from_probes"]

#: Columns of a backbone family's probe edge (one row per protocol).
FAMILY_COLUMNS = (
    "row_id",
    "family",
    "vision_backbone",
    "tactile_backbone",
    "probe",
    "corpus",
    "null_corpus",
    "target",
    "metric",
    "protocol",
    "n_train",
    "n_test",
    "dim_v",
    "dim_t",
    "status",
    *MAIN_STATISTICS,
    "notes",
)


def backbone_family_rows(
    family: str,
    probe: str,
    rows: FamilyRows,
    *,
    vision: tuple[np.ndarray, np.ndarray],
    tactile: tuple[np.ndarray, np.ndarray],
    probes_cfg: Mapping,
    kind: str,
    protocols: Sequence[str],
    seed: int,
    labels: Mapping[str, str],
    null_corpus: bool,
    progress: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """V vs V+T (concat) of probe family `probe` on `family`'s features, one row per protocol.

    vision, tactile: (train, test) feature matrices in `rows`' order. labels: the vision and
    tactile backbones' report labels. A protocol whose probe cannot be fitted is a ``failed``
    row naming why (the others still run).
    """
    say = progress or (lambda _m: None)
    out = []
    for protocol in protocols:
        settings = ProbeSettings.from_config(probes_cfg, kind, seed, protocol)
        base = {
            "row_id": f"{family}|{probe}|{protocol}",
            "family": family,
            "vision_backbone": labels["vision"],
            "tactile_backbone": labels["tactile"],
            "probe": probe,
            "corpus": rows.corpus,
            "null_corpus": bool(null_corpus),
            "target": rows.target,
            "metric": settings.metric,
            "protocol": protocol,
            "n_train": rows.n_train,
            "n_test": rows.n_test,
            "dim_v": int(vision[0].shape[1]),
            "dim_t": int(tactile[0].shape[1]),
        }
        try:
            res = compare(
                vision[0],
                vision[1],
                tactile[0],
                tactile[1],
                rows,
                "concat",
                settings,
                controls=False,
            )
        except ValueError as exc:
            out.append({**base, "status": "failed", "notes": f"probe could not be fitted: {exc}"})
            say(f"{family} {probe} {protocol}: failed ({exc})")
            continue
        m = res.main
        out.append(
            {**base, "status": "ok", **{c: m[c] for c in MAIN_STATISTICS}, "notes": m["notes"]}
        )
        say(
            f"{family} {probe} {protocol}: V {m['v_score']:.3f}, V+T {m['vt_score']:.3f}, "
            f"delta {m['delta']:+.3f} [{m['ci_low']:+.3f}, {m['ci_high']:+.3f}]"
        )
    return comparison_frame(out, FAMILY_COLUMNS)


def rows_from_probes(
    probe_rows: Mapping[tuple[str, str], pd.DataFrame],
    *,
    family: str,
    heads_variant: str,
    labels: Mapping[str, str],
) -> pd.DataFrame:
    """The main family's rows, taken from the probes stage's edges instead of computed again.

    probe_rows: (probe family, protocol) -> that probe job's edge (rule probe). Its headline
    row is kept: raw V vs V+T with `concat` on `heads_variant`, no control. A job without one
    such row is refused naming the probe family and protocol.
    """
    out = []
    for (probe, protocol), frame in probe_rows.items():
        hit = frame[
            (frame["input"] == "raw")
            & (frame["fusion"] == "concat")
            & (frame["t_variant"] == heads_variant)
            & (frame["control"] == "none")
        ]
        if len(hit) != 1:
            raise ValueError(
                f"probe family {probe!r}, protocol {protocol!r}: {len(hit)} headline rows (raw "
                f"V vs V+T concat on {heads_variant!r}, no control) in its probe edge, expected 1"
            )
        r = hit.iloc[0]
        out.append(
            {
                "row_id": f"{family}|{probe}|{protocol}",
                "family": family,
                "vision_backbone": labels["vision"],
                "tactile_backbone": labels["tactile"],
                "probe": probe,
                "corpus": r["corpus"],
                "null_corpus": bool(r["null_corpus"]),
                "target": r["target"],
                "metric": r["metric"],
                "protocol": protocol,
                "n_train": int(r["n_train"]),
                "n_test": int(r["n_test"]),
                "dim_v": int(r["dim_v"]),
                "dim_t": int(r["dim_vt"]) - int(r["dim_v"]),
                "status": r["status"],
                **{c: r[c] for c in ("v_score", "vt_score", "delta", "ci_low", "ci_high", "p_gt0")},
                "n_resamples": r["n_resamples"],
                "notes": "the probes stage's headline row (rule probe)",
            }
        )
    return comparison_frame(out, FAMILY_COLUMNS)
