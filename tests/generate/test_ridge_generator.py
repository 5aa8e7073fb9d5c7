"""The ridge V->T generator (tacgen_lib.generate.ridge_generator) against float64 references: its mean is
the closed-form ridge solution at the penalty that brute-force leave-one-out picks, also with
fewer train rows than visual dimensions; its residual arm adds train residuals, seeded; and in
the evaluation a generator equal to it scores exactly as it."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tacgen_lib.generate.ridge_generator import RIDGE_ALPHAS, ridge_generate


def linear_world(n: int, d_v: int, d_t: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, d_v))
    t = v @ rng.normal(size=(d_v, d_t)) + 0.5 * rng.normal(size=(n, d_t)) + 3.0
    ids = [f"s{i:03d}" for i in range(n)]
    return ids, dict(zip(ids, v, strict=True)), dict(zip(ids, t, strict=True))


def closed_form(x: np.ndarray, y: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """Ridge with an unpenalised intercept in float64: (coefficients, intercept)."""
    xm, ym = x.mean(0), y.mean(0)
    xc, yc = x - xm, y - ym
    beta = np.linalg.solve(xc.T @ xc + alpha * np.eye(x.shape[1]), xc.T @ yc)
    return beta, ym - xm @ beta


def loo_error(x: np.ndarray, y: np.ndarray, alpha: float) -> float:
    """Mean squared leave-one-out error over all outputs, one refit per left-out row."""
    errs = []
    for i in range(len(x)):
        keep = np.arange(len(x)) != i
        beta, b0 = closed_form(x[keep], y[keep], alpha)
        errs.append((x[i] @ beta + b0 - y[i]) ** 2)
    return float(np.mean(errs))


@pytest.mark.parametrize(("n_train", "d_v"), [(60, 5), (12, 20)])  # n > d, and n < d
def test_mean_is_closed_form_ridge_at_the_leave_one_out_penalty(n_train, d_v):
    ids, vision, t_real = linear_world(80, d_v, 3)
    train = ids[:n_train]
    got = ridge_generate(vision, t_real, train, seed=0)
    x = np.stack([vision[i] for i in train])
    y = np.stack([t_real[i] for i in train])
    errors = [loo_error(x, y, a) for a in RIDGE_ALPHAS]
    assert got.alpha == RIDGE_ALPHAS[int(np.argmin(errors))]
    beta, b0 = closed_form(x, y, got.alpha)
    for i in ids:  # every row of the corpus, train or not
        np.testing.assert_allclose(got.mean[i], vision[i] @ beta + b0, rtol=1e-9, atol=1e-9)
    assert got.n_train == n_train and set(got.mean) == set(ids) == set(got.residual)


def test_residual_arm_adds_a_seeded_train_residual():
    ids, vision, t_real = linear_world(50, 4, 2)
    train = ids[:30]
    a, b = (
        ridge_generate(vision, t_real, train, seed=1),
        ridge_generate(vision, t_real, train, seed=1),
    )
    other = ridge_generate(vision, t_real, train, seed=2)
    residuals = np.stack([t_real[i] - a.mean[i] for i in sorted(train)])
    for i in ids:
        np.testing.assert_array_equal(a.residual[i], b.residual[i])  # the same draw twice
        added = a.residual[i] - a.mean[i]
        # the added vector is one of the train residuals (within the rounding of one addition)
        assert np.min(np.abs(residuals - added).max(axis=1)) < 1e-12
    assert any(not np.array_equal(a.residual[i], other.residual[i]) for i in ids)
    # the draw follows the sorted ids, not the mapping's order
    flipped = ridge_generate(dict(reversed(vision.items())), t_real, train[::-1], seed=1)
    for i in ids:
        np.testing.assert_array_equal(flipped.residual[i], a.residual[i])


def test_ridge_generator_refuses_too_few_or_unknown_train_rows():
    ids, vision, t_real = linear_world(10, 3, 2)
    with pytest.raises(ValueError, match="at least 2 train rows, got 1"):
        ridge_generate(vision, t_real, ids[:1], seed=0)
    with pytest.raises(ValueError, match="train row 'nope' has no vision or tactile vector"):
        ridge_generate(vision, t_real, [*ids[:3], "nope"], seed=0)


def test_a_generator_equal_to_ridge_scores_as_ridge_in_the_evaluation():
    """evaluate_generator fits the ridge generator on the generator's train rows: a diffusion
    cell that returns exactly its mean has Delta_gen - ridge = 0 with a [0, 0] interval, and
    the ridge rows carry their own fidelity (matched cosine above off-diagonal on a linear map)."""
    from generate_worlds import evaluate_one, small_probes

    from tacgen_lib.generate.baselines import TargetSpec
    from tacgen_lib.probes.rows import family_rows

    ids, vision, t_real = linear_world(90, 4, 3, seed=4)
    split = ["test" if k % 5 == 0 else "val" if k % 5 == 1 else "train" for k in range(90)]
    splits = pd.DataFrame({"sample_id": ids, "corpus": "toy", "split": split})
    manifest = pd.DataFrame(
        {"sample_id": ids, "corpus": "toy", "force_p50": [t_real[i][0] for i in ids]}
    )
    rows = family_rows(manifest, splits, corpus="toy", target="force_p50", kind="ridge")
    spec = TargetSpec("force_p50", rows, small_probes("ridge", [0.1, 1, 10], [1]))
    train = [i for i, s in zip(ids, split, strict=True) if s == "train"]
    ridge = ridge_generate(vision, t_real, train, seed=3)
    t_gen = {("ddim", "1", "5"): ridge.mean}
    summary, _ = evaluate_one(
        spec, vision, t_real, t_gen, seed=3, permutations=20, generator_train_ids=train
    )
    by = summary.set_index("input")
    gen = by.loc["t_gen"]
    assert (gen["delta_vs_ridge"], gen["ci_low_vs_ridge"], gen["ci_high_vs_ridge"]) == (0, 0, 0)
    assert gen["score"] == by.loc["t_ridge", "score"]
    assert by.drop(index="t_gen")["delta_vs_ridge"].isna().all()
    for arm in ("t_ridge", "t_ridge_residual"):
        assert by.loc[arm, "cos_matched"] > by.loc[arm, "cos_offdiag"]
    assert by.loc["t_ridge", "ridge_alpha"] == ridge.alpha
