"""Transfer to a second sensor (tacgen_lib.probes.transfer): balanced accuracy and its
object-level bootstrap against scikit-learn, mass-quantile classes against pandas, the
shuffled-touch control, and the evaluation on synthetic objects where touch does and does
not carry the label."""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.metrics import balanced_accuracy_score

from tacgen_lib.corpus.objects import mass_quantile_classes
from tacgen_lib.probes.bootstrap import resample_counts, resample_indices
from tacgen_lib.probes.metrics import balanced_accuracy, balanced_accuracy_resamples
from tacgen_lib.probes.transfer import (
    TRANSFER_COLUMNS,
    TransferSettings,
    TransferSplit,
    evaluate_transfer,
    evaluate_transfer_seeds,
    fit_objects,
    shuffled_by_object,
)
from tacgen_lib.report import findings
from tacgen_lib.report import transfer as report
from tacgen_lib.report.write import figure_problems

labels = st.lists(st.integers(0, 3), min_size=1, max_size=40)


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """scikit-learn warns when the predictions hold a class the truth lacks."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_balanced_accuracy_equals_scikit_learn(data):
    y = np.array(data.draw(labels))
    p = np.array(data.draw(st.lists(st.integers(0, 3), min_size=len(y), max_size=len(y))))
    with _quiet():  # scikit-learn warns when p holds a class y lacks
        want = balanced_accuracy_score(y, p)
    assert balanced_accuracy(y, p) == pytest.approx(want, abs=1e-12)


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 9), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_object_bootstrap_equals_listing_the_resampled_rows_out(n_objects, contacts, seed):
    """Each resample's balanced accuracy from draw counts equals scikit-learn's on that
    resample's rows listed out (every drawn object with all its contacts, as often as drawn)."""
    rng = np.random.default_rng(seed)
    groups = np.repeat(np.arange(n_objects), contacts)
    y = rng.integers(0, 3, n_objects)[groups]
    p = rng.integers(0, 3, groups.size)
    idx = resample_indices(n_objects, 25, seed)
    got = balanced_accuracy_resamples(y, p, groups, resample_counts(idx, n_objects))
    for b in range(idx.shape[0]):
        rows = np.concatenate([np.flatnonzero(groups == g) for g in idx[b]])
        with _quiet():
            want = balanced_accuracy_score(y[rows], p[rows])
        assert got[b] == pytest.approx(want, abs=1e-12)


def test_mass_quantile_classes_are_pandas_qcut_and_refuse_what_cannot_be_classed():
    mass = np.random.default_rng(1).lognormal(size=37)
    np.testing.assert_array_equal(
        mass_quantile_classes(mass, 3, where="x"), pd.qcut(mass, 3, labels=False)
    )
    assert np.bincount(mass_quantile_classes(mass[:36], 3, where="x")).tolist() == [12, 12, 12]
    with pytest.raises(ValueError, match="corpus z: 2 object"):
        mass_quantile_classes(mass[:2], 3, where="corpus z")
    with pytest.raises(ValueError, match="tie at a quantile edge"):
        mass_quantile_classes(np.ones(9), 3, where="corpus z")


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 12), st.integers(1, 4), st.integers(0, 1000))
def test_shuffled_touch_always_comes_from_another_object(n_objects, contacts, seed):
    objects = np.repeat(np.arange(n_objects) * 7, contacts)  # any object ids
    rows = shuffled_by_object(objects, seed)
    assert (objects[rows] != objects).all()
    # each object's rows take one donor object's rows
    donors = pd.Series(objects[rows]).groupby(objects).nunique()
    assert (donors == 1).all()
    with pytest.raises(ValueError, match="at least 2 objects"):
        shuffled_by_object(np.zeros(3, dtype=int), seed)


def test_fit_objects_draws_within_each_class():
    objects = np.arange(20)
    cls = objects % 3
    got = fit_objects(objects, cls, 0.5, seed=4)
    assert np.array_equal(got, fit_objects(objects, cls, 0.5, seed=4))
    assert sorted(np.bincount(cls[got]).tolist()) == [3, 4, 4]  # round(0.5 x 7, 7, 6)
    assert len(set(fit_objects(objects, cls, 0.5, seed=5)) ^ set(got)) > 0


def _synthetic(signal: float, seed: int = 0, n_objects: int = 36, contacts: int = 6):
    """Objects with a mass class; V is noise, T carries the class with strength `signal`
    (a per-object value shared by its contacts, plus per-contact noise)."""
    rng = np.random.default_rng(seed)
    objects = np.repeat(np.arange(n_objects), contacts)
    mass = rng.lognormal(size=n_objects)
    y = mass_quantile_classes(mass, 3, where="synthetic")[objects]
    order = np.argsort(mass)  # deal objects so that every class has test objects
    dealt = np.empty(n_objects, dtype=object)
    dealt[order] = np.resize(["train", "test", "train", "val", "test", "train"], n_objects)
    split = dealt[objects]
    V = rng.normal(size=(objects.size, 16))
    T = rng.normal(size=(objects.size, 16))
    T[:, :3] += signal * np.eye(3)[y]
    return V, T, TransferSplit(y=y, objects=objects, split=split)


SMALL = TransferSettings(probe_seeds=(42, 43, 44), bootstrap=1000, C=(0.1, 1.0))


def test_touch_that_carries_the_class_shows_a_gain_that_beats_the_shuffled_control():
    V, T, split = _synthetic(signal=3.0)
    out = evaluate_transfer({"none": (V, T)}, split, SMALL)
    assert list(out.columns) == list(TRANSFER_COLUMNS)
    mean = out[out["probe_seed"] == "mean"].iloc[0]
    assert mean["delta_ci_low"] > 0
    assert mean["positive_seeds"] == 3
    assert mean["delta_ci_low"] > mean["delta_shuffled_ci_high"]
    assert mean["chance"] == pytest.approx(1 / 3)
    again = evaluate_transfer({"none": (V, T)}, split, SMALL)
    pd.testing.assert_frame_equal(out, again)  # the same computation twice: bit identical


def test_touch_without_the_class_shows_no_gain():
    V, T, split = _synthetic(signal=0.0)
    out = evaluate_transfer({"none": (V, T)}, split, SMALL)
    mean = out[out["probe_seed"] == "mean"].iloc[0]
    assert mean["delta_ci_low"] < 0 < mean["delta_ci_high"]


def test_a_split_that_mixes_an_objects_rows_or_misses_a_class_in_test_is_refused():
    V, T, split = _synthetic(signal=1.0, n_objects=12, contacts=2)
    mixed = split.split.copy()
    mixed[0], mixed[1] = "train", "test"
    with pytest.raises(ValueError, match="object 0 has rows of different classes or splits"):
        TransferSplit(split.y, split.objects, mixed)
    no_test = np.where(split.y == 2, "train", split.split)
    with pytest.raises(ValueError, match=r"mass class\(es\) \[2\] have no test object"):
        TransferSplit(split.y, split.objects, no_test)


def test_the_page_reads_the_summary():
    V, T, split = _synthetic(signal=3.0)
    rng = np.random.default_rng(3)
    views = {"none": (V, T), "source": (V, rng.normal(size=T.shape))}
    out = evaluate_transfer(views, split, SMALL, heads_from={"source": "sim_paired"})
    table = report.transfer_table(out)
    assert len(table) == len(out) == 2 * 4
    assert table["probe seed"].iloc[3].startswith("mean of 3 (3/3 Δ > 0)")
    notes = report.transfer_sentences(out, "sim_transfer")
    assert len(notes) == 3 and "12 test objects" in notes[0]
    assert "V+T helps" in notes[1] and "above the shuffled-touch control" in notes[1]
    assert "sim_paired" in notes[2]
    assert "weaker V" not in notes[2]  # the source view's V is the frozen V here
    weaker = out.copy()
    weaker.loc[weaker["heads"] == "source", "ba_v"] -= 0.1
    flagged = report.transfer_sentences(weaker, "sim_transfer")[2]
    assert "scores below the frozen features' V" in flagged and "against the frozen V" in flagged
    fig = report.transfer_figure(out, "sim_transfer")
    assert figure_problems(fig) == []
    part = findings.transfer_findings(out)
    row = part.rows.iloc[0]
    assert [d["decision_id"] for d in part.decisions][:2] == [
        "transfer|source",
        "transfer|source_vs_shuffled",
    ]
    assert row["page"].endswith("Transfer to a second sensor")
    assert "heads from sim_paired" in row["result"] and "not run" in row["result"]
    assert row["verdict"].startswith(("No measurable difference", "V+T"))


def test_every_heads_seed_is_a_replicate_and_one_seed_alone_decides_nothing():
    """Two heads seeds: one whose touch carries the class, one whose does not. The page has a
    row per (view, heads seed, probe seed); the findings read the transfer over both heads
    seeds (claims.seeds_interval), so the gain one draw of the heads shows is not called one."""
    V, T, split = _synthetic(signal=3.0)
    noise = np.random.default_rng(5).normal(size=T.shape)
    aligned = {42: {"source": (V, T)}, 43: {"source": (V, noise)}}
    out = evaluate_transfer_seeds(
        (V, T), aligned, split, SMALL, heads_from={"source": "sim_paired"}
    )
    assert list(out.columns) == list(TRANSFER_COLUMNS)
    assert out["row_id"].is_unique and len(out) == 3 * 4
    assert set(out["heads_seed"]) == {"", "42", "43"}
    assert set(out.loc[out["heads"] == "none", "heads_seed"]) == {""}
    means = out[(out["probe_seed"] == "mean") & (out["heads"] == "source")]
    by_seed = means.set_index("heads_seed")
    assert by_seed.loc["42", "delta_ci_low"] > 0 >= by_seed.loc["43", "delta_ci_low"]
    # the seed-42 rows are evaluate_transfer's own on that seed's view
    alone = evaluate_transfer({"source": (V, T)}, split, SMALL, heads_from={"source": "sim_paired"})
    got = out[out["heads_seed"] == "42"].reset_index(drop=True)
    np.testing.assert_allclose(got["delta"], alone["delta"], rtol=1e-12)
    part = findings.transfer_findings(out)
    source = next(d for d in part.decisions if d["decision_id"] == "transfer|source")
    assert source["decision"] != "above 0"
    assert source["ci_low"] == pytest.approx(means["delta_ci_low"].min())
    assert "over 2 heads seeds" in part.rows.iloc[0]["result"]
    # only the first seed's heads: the gain is called
    first = findings.transfer_findings(out[out["heads_seed"] != "43"])
    assert (
        next(d for d in first.decisions if d["decision_id"] == "transfer|source")["decision"]
        == "above 0"
    )
    table = report.transfer_table(out)
    assert list(table["heads seed"].unique()) == ["–", "42", "43"]
    assert len(report.transfer_sentences(out, "sim_transfer")) == 1 + 3
    assert figure_problems(report.transfer_figure(out, "sim_transfer")) == []
    with pytest.raises(ValueError, match="no alignment seed"):
        evaluate_transfer_seeds((V, T), {}, split, SMALL)
