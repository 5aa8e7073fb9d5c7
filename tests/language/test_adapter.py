"""Tactile-to-language evidence (tacgen_lib.language.adapter): captions from ground truth with
thresholds from train rows only, the offline text encoder and the adapter against
scikit-learn, forced choices that read a perfect tactile code perfectly and a shuffled one at
chance, and the hard cases (a single-word attribute, a corpus without the columns)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from sklearn.feature_extraction.text import TfidfVectorizer
from sklearn.linear_model import RidgeCV

from tacgen_lib.language.adapter import (
    ADAPTER_ALPHAS,
    ATTRIBUTES,
    attribute_labels,
    caption_for,
    fit_adapter,
    fit_text_encoder,
    forced_choice,
    language_evidence,
)


def world(n: int = 300, seed: int = 0, noise: float = 0.1):
    """Samples whose touch codes hardness, mass and friction linearly, plus noise."""
    rng = np.random.default_rng(seed)
    hard = rng.random(n) < 0.6
    mass = rng.lognormal(-3, 1, n)
    friction = rng.uniform(0.3, 1.2, n)
    ids = [f"s{i:04d}" for i in range(n)]
    manifest = pd.DataFrame(
        {
            "sample_id": ids,
            "hardness": np.where(hard, "hard", "soft"),
            "mass": mass,
            "friction": friction,
        }
    )
    code = np.column_stack([hard * 2.0 - 1, np.log(mass) + 3, (friction - 0.75) * 4])
    t = code @ rng.normal(size=(3, 12)) + noise * rng.normal(size=(n, 12))
    return manifest, ids, dict(zip(ids, t, strict=True))


def test_thresholds_come_from_train_rows_only():
    manifest, ids, _ = world(40)
    train, test = ids[:30], ids[30:]
    got = attribute_labels(manifest, train)
    median = manifest.set_index("sample_id").loc[train, "mass"].median()
    heavy = manifest.set_index("sample_id")["mass"] > median
    assert (got["weight"] == np.where(heavy, "heavy", "light")).all()
    # moving a test row's mass moves no train row's word
    moved = manifest.copy()
    moved.loc[moved["sample_id"] == test[0], "mass"] = 1e6
    again = attribute_labels(moved, train)
    assert (again.loc[train, "weight"] == got.loc[train, "weight"]).all()
    assert caption_for(got.loc[ids[0]], 0).startswith(f"a {got.loc[ids[0], 'hardness']} ")


def test_single_word_attributes_and_missing_columns_are_left_out():
    manifest, ids, _ = world(40)
    one_class = manifest.assign(hardness="hard")
    assert list(attribute_labels(one_class, ids)) == ["weight", "grip"]
    real = manifest[["sample_id", "hardness"]]  # a real corpus: no mass, no friction
    assert list(attribute_labels(real, ids)) == ["hardness"]
    assert caption_for({"hardness": "soft"}, 0) == "a soft unknown object that feels unknown"
    with pytest.raises(ValueError, match="no attribute has both"):
        attribute_labels(real.assign(hardness="soft"), ids)
    with pytest.raises(ValueError, match="'s0000' has hardness 'squishy'"):
        attribute_labels(manifest.assign(hardness=["squishy"] + ["hard"] * 39), ids)


def test_encoder_and_adapter_are_scikit_learns():
    combos = [
        {"hardness": h, "weight": m, "grip": g}
        for h in ("hard", "soft")
        for m in ("heavy", "light")
        for g in ("grippy", "slippery")
    ]
    captions = [caption_for(w, k) for k, w in enumerate(combos)]
    enc = fit_text_encoder(captions)
    ref = TfidfVectorizer(token_pattern=r"[a-z]+").fit(captions)
    np.testing.assert_array_equal(enc.encode(captions), ref.transform(captions).toarray())
    assert enc.dim == len(ref.vocabulary_)
    with pytest.raises(ValueError, match="1 distinct word"):
        fit_text_encoder(["hard hard", "hard"])
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(40, 5)), rng.normal(size=(40, 3))
    got = fit_adapter(x, y)
    want = RidgeCV(alphas=list(ADAPTER_ALPHAS)).fit(x, y)
    assert got.alpha_ == want.alpha_
    np.testing.assert_allclose(got.predict(x), want.predict(x), rtol=1e-12)


def test_touch_that_codes_the_words_reads_them_and_shuffled_touch_does_not():
    manifest, ids, t = world(400, noise=0.05)
    train, test = ids[:300], ids[300:]
    rows = language_evidence(manifest, train, test, t, t, corpus="toy", bootstrap=500, seed=0)
    acc = rows.set_index(["attribute", "input"])["accuracy"]
    for attr in ATTRIBUTES:
        assert acc[(attr, "real")] > 0.9, attr
        assert acc[(attr, "generated")] == acc[(attr, "real")]  # generated = real here
        assert acc[(attr, "shuffled_generated")] < 0.75, attr
    # the majority column: the test accuracy of always choosing the train rows' commoner word
    words = attribute_labels(manifest, train)
    for attr in ATTRIBUTES:
        counts = words.loc[train, attr].value_counts()
        common = sorted(counts.index[counts == counts.max()])[0]  # ties: the first word
        want = float(np.mean(words.loc[test, attr] == common))
        assert (rows.loc[rows["attribute"] == attr, "majority"] == want).all(), attr
    gen = rows[rows["input"] == "generated"]
    assert (gen["ci_low_vs_shuffled"] > 0).all()
    # the same computation twice: bit for bit
    pd.testing.assert_frame_equal(
        rows,
        language_evidence(manifest, train, test, t, t, corpus="toy", bootstrap=500, seed=0),
    )


def test_forced_choice_ties_go_to_the_first_word():
    manifest, ids, t = world(60)
    words = attribute_labels(manifest, ids)
    captions = [caption_for(words.loc[i], k) for k, i in enumerate(ids)]
    enc = fit_text_encoder(captions)
    adapter = fit_adapter(np.stack([t[i] for i in ids]), enc.encode(captions))
    adapter.coef_[:] = 0.0
    adapter.intercept_[:] = 0.0  # every adapted vector is 0: every cosine ties at 0
    got = forced_choice(adapter, enc, np.stack([t[i] for i in ids[:5]]))
    assert all((got[a] == ATTRIBUTES[a][0]).all() for a in ATTRIBUTES)
