"""Real + generated alignment retraining: the generated-fraction scale curve (paper, Pix2Pix).

The InfoNCE heads are retrained with generated tactile features in place of real ones on a
fraction p of their training rows (train and validation alike, each split's own seeded draw),
then judged as the probes stage judges heads: V_aligned vs concat(V_aligned, T_aligned) on the
probe rows, where T_aligned projects the REAL tactile features of every row (held-out real
touch), with the probes' fixed-test bootstrap CI. Generated touch that carries information
keeps the gain as p grows; the control replaces the same rows with a shuffled generator
(row i gets the frame generated for another row: `evaluate.shuffled_rows`), which keeps the
generated marginal and breaks the pairing.

At p = 0 no row is replaced: the point is the real-only heads and both pairings share it.
The corpora here have no vision-only rows, so no extra generated rows are added; a corpus
with them would add generated tactile for those rows to the heads' training set.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
import pandas as pd

from tacgen_lib.generate.baselines import TargetSpec
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.evaluate import shuffled_rows

__all__ = ["CURVE_COLUMNS", "PAIRINGS", "curve_point", "mixed_tactile", "replaced_rows"]

#: How the replaced rows get their generated tactile: their own frame, or another row's.
PAIRINGS = ("generated", "shuffled")

CURVE_COLUMNS = (
    "row_id",
    "corpus",
    "generator",
    "seed",
    "fraction",
    "pairing",
    "n_replaced",
    "target",
    "metric",
    "v_score",
    "score",
    "delta",
    "ci_low",
    "ci_high",
    "p_gt0",
    "top1_v2t",
    "chance_top1",
)


def replaced_rows(ids: Sequence[str], fraction: float, seed: int) -> list[str]:
    """round(fraction * len(ids)) of `ids` drawn without replacement (seeded), sorted."""
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"generated fraction must lie in [0, 1], got {fraction}")
    ids = sorted(str(i) for i in ids)
    k = int(round(fraction * len(ids)))
    pick = np.random.default_rng(seed).permutation(len(ids))[:k]
    return sorted(ids[i] for i in pick)


def mixed_tactile(
    t_real: Mapping[str, np.ndarray],
    t_gen: Mapping[str, np.ndarray],
    replaced: Sequence[str],
    *,
    pairing: str,
    seed: int,
) -> dict[str, np.ndarray]:
    """sample_id -> tactile vector: generated on the `replaced` rows, real elsewhere.

    pairing ``generated``: row i gets the vector generated from row i's RGB; ``shuffled``: the
    vector generated for row perm(i), a seeded permutation of all rows without fixed points.
    """
    if pairing not in PAIRINGS:
        raise ValueError(f"pairing must be one of {PAIRINGS}, got {pairing!r}")
    missing = sorted(set(t_real) ^ set(t_gen))
    if missing:
        raise ValueError(
            f"mixed_tactile: sample_id {missing[0]!r} has a real or a generated vector, not both"
        )
    out = dict(t_real)
    if pairing == "generated":
        source = t_gen
    else:
        ids = np.array(sorted(t_gen), dtype=object)
        perm = shuffled_rows(len(ids), seed)
        source = {i: t_gen[j] for i, j in zip(ids, ids[perm], strict=True)}
    for i in replaced:
        out[i] = source[i]
    return out


def curve_point(
    targets: Sequence[TargetSpec],
    *,
    corpus: str,
    generator: str,
    seed: int,
    fraction: float,
    pairing: str,
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    t_gen: Mapping[str, np.ndarray],
    head_ids: Mapping[str, Sequence[str]],
    fit_heads: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], object],
    project: Callable[[object, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
) -> pd.DataFrame:
    """One point of the curve: heads trained with generated touch on a fraction of their rows,
    then the probes on real touch (module docstring). Rows: one per target (`CURVE_COLUMNS`).

    head_ids: {"train", "val", "test"} sample ids of the heads (the split guard has checked
    them); `fit_heads(v, t, train_idx, val_idx)` trains the heads on the stacked train + val
    rows (`tacgen_lib.align.train.fit_heads` with tau, seed and settings bound), `project`
    projects V and T features through them (`tacgen_lib.align.heads.project`). Passing them in
    keeps this module free of torch.
    """
    from tacgen_lib.align.retrieval import paired_retrieval
    from tacgen_lib.probes.bootstrap import fixed_test_bootstrap
    from tacgen_lib.probes.fit import fit_probe

    train, val = list(head_ids["train"]), list(head_ids["val"])
    replaced = replaced_rows(train, fraction, seed) + replaced_rows(val, fraction, seed + 1)
    mixed = mixed_tactile(t_real, t_gen, replaced, pairing=pairing, seed=seed)
    fit_ids = train + val
    heads = fit_heads(
        feature_block(vision, fit_ids).astype(np.float32),
        feature_block(mixed, fit_ids).astype(np.float32),
        np.arange(len(train)),
        np.arange(len(train), len(fit_ids)),
    )
    ids = sorted(vision)
    z_v, z_t = project(
        heads,
        feature_block(vision, ids).astype(np.float32),
        feature_block(t_real, ids).astype(np.float32),
    )
    zv = dict(zip(ids, z_v, strict=True))
    zt = dict(zip(ids, z_t, strict=True))
    test = list(head_ids["test"])
    retrieval = paired_retrieval(feature_block(zv, test), feature_block(zt, test))
    out = []
    for spec in targets:
        rows, ps = spec.rows, spec.settings
        v_tr, v_te = feature_block(zv, rows.train_ids), feature_block(zv, rows.test_ids)
        t_tr, t_te = feature_block(zt, rows.train_ids), feature_block(zt, rows.test_ids)

        def fit(x_tr: np.ndarray, x_te: np.ndarray, rows=rows, ps=ps) -> np.ndarray:
            return fit_probe(
                x_tr, rows.y_train, x_te, ps, train_ids=rows.train_ids, test_ids=rows.test_ids
            ).pred_test

        boot = fixed_test_bootstrap(
            rows.y_test,
            fit(v_tr, v_te),
            fit(np.hstack([v_tr, t_tr]), np.hstack([v_te, t_te])),
            ps.metric,
            n_resamples=ps.bootstrap,
            seed=ps.seed,
            strata=rows.strata_test,
            sample_ids=rows.test_ids,
        )
        out.append(
            {
                "row_id": f"{corpus}|{generator}|seed~{seed}|p~{fraction:g}|{pairing}|{spec.name}",
                "corpus": corpus,
                "generator": generator,
                "seed": int(seed),
                "fraction": float(fraction),
                "pairing": pairing,
                "n_replaced": len(replaced),
                "target": spec.name,
                "metric": ps.metric,
                "v_score": boot["v_score"],
                "score": boot["vt_score"],
                "delta": boot["delta"],
                "ci_low": boot["ci_low"],
                "ci_high": boot["ci_high"],
                "p_gt0": boot["p_gt0"],
                "top1_v2t": float(retrieval["top1_v2t"]),
                "chance_top1": float(retrieval["chance_top1"]),
            }
        )
    return pd.DataFrame(out, columns=list(CURVE_COLUMNS))
