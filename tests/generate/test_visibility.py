"""The visibility check (tacgen_lib.generate.visibility): each visible factor decoded from V by
a linear and a nonlinear probe on every non-test row, a factor with one level left out, the
same rows in forked workers, the gate, and the page's table, figure and sentence."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from generate_worlds import small_probes
from threadpoolctl import threadpool_limits

from tacgen_lib.generate.visibility import (
    VISIBILITY_COLUMNS,
    VisibilityCorpus,
    VisibilitySettings,
    visibility_check,
    visibility_gate,
)
from tacgen_lib.probes.settings import ProbeSettings


def _probe() -> ProbeSettings:
    return small_probes("logistic", [1.0], [0.1, 1, 10], controls=2, seed=42)


def _corpus(n: int = 300, seed: int = 0) -> VisibilityCorpus:
    """V codes colour linearly and texture by the magnitude of one column (|a| > 0.67: about
    half the rows; no linear probe can read a symmetric code); every frame is one shape."""
    rng = np.random.default_rng(seed)
    colour = rng.integers(3, size=n)
    a = rng.normal(size=n)
    texture = (np.abs(a) > 0.67).astype(int)
    v = np.column_stack([np.eye(3)[colour] * 2, a, rng.normal(size=n)])
    v += 0.05 * rng.normal(size=v.shape)
    ids = [f"c-{i:04d}" for i in range(n)]
    factors = pd.DataFrame(
        {
            "colour": colour.astype(str),
            "texture": texture.astype(str),
            "shape": "cube",
            "size": np.where(rng.random(n) < 0.5, "small", "large"),
        },
        index=pd.Index(ids, name="sample_id"),
    )
    return VisibilityCorpus("toy", dict(zip(ids, v, strict=True)), factors, ids[60:], ids[:60])


def _check(workers: int = 1) -> pd.DataFrame:
    return visibility_check(
        [_corpus()], _probe(), VisibilitySettings(gammas=(1.0,), bootstrap=200), workers=workers
    )


def test_each_shown_factor_gets_both_probes_and_a_single_level_none():
    rows = _check()
    assert list(rows.columns) == list(VISIBILITY_COLUMNS)
    assert list(zip(rows["factor"], rows["probe"], strict=True)) == [
        ("colour", "linear"),
        ("colour", "nonlinear"),
        ("texture", "linear"),
        ("texture", "nonlinear"),
        ("size", "linear"),
        ("size", "nonlinear"),
    ]  # shape has one level: nothing to decode
    by = rows.set_index(["factor", "probe"])["score"]
    assert by["colour", "linear"] > 0.95
    # texture is |a|: the nonlinear probe reads it, the linear cannot
    assert by["texture", "nonlinear"] > by["texture", "linear"] + 0.15
    assert (rows["ci_low"] <= rows["score"]).all() and (rows["score"] <= rows["ci_high"]).all()
    assert (rows["n"] == 240).all() and (rows["n_test"] == 60).all()


def test_forked_workers_give_the_rows_of_one_process():
    with threadpool_limits(1):
        alone = _check(1)
    pd.testing.assert_frame_equal(_check(2), alone)


def test_a_row_without_factors_is_refused_naming_it():
    c = _corpus()
    bad = VisibilityCorpus(c.name, c.vision, c.factors.iloc[1:], c.train, c.test)
    with pytest.raises(ValueError, match="sample_id 'c-0000' has no visible factors"):
        visibility_check([bad], _probe(), VisibilitySettings())


def test_the_gate_reads_the_better_probe_and_fails_a_factor_not_shown():
    rows = _check()
    ok = visibility_gate(rows, "toy", {"colour": 0.9})
    assert ok.passed and "passes" in ok.sentence()
    shape = visibility_gate(rows, "toy", {"colour": 0.9, "shape": 0.5})
    assert not shape.passed and "cannot show whether generated touch helps" in shape.sentence()
    tex = rows[(rows["factor"] == "texture")]["score"].max()
    assert not visibility_gate(rows, "toy", {"texture": min(1.0, tex + 0.01)}).passed


def test_settings_refuse_an_unknown_factor_or_a_gate_outside_0_1():
    with pytest.raises(ValueError, match="'weight'"):
        VisibilitySettings(gate={"weight": 0.5})
    with pytest.raises(ValueError, match=r"gate\.colour must be .* <= 1, got 1\.5"):
        VisibilitySettings.from_config({"gate": {"colour": 1.5}})


def test_the_page_reads_the_rows():
    import matplotlib

    matplotlib.use("Agg")
    from tacgen_lib.report.visibility import (
        visibility_figure,
        visibility_sentence,
        visibility_table,
    )
    from tacgen_lib.report.write import figure_problems

    rows = _check()
    table = visibility_table(rows)
    assert list(table["factor"]) == ["colour", "texture", "size"]
    sentence = visibility_sentence(rows, "toy")
    best = rows[rows["factor"] == "texture"]["score"].max()
    assert sentence.startswith("V sees, on toy: colour") and f"texture {best:.3f}" in sentence
    fig = visibility_figure(pd.concat([rows, rows.assign(corpus="toy2")]))
    assert figure_problems(fig) == []


def test_a_corpus_showing_anothers_frames_gets_its_rows_without_refitting():
    c = _corpus()
    rename = {i: i.replace("c-", "n-") for i in c.factors.index}
    twin = VisibilityCorpus(
        "toy_null",
        {rename[i]: v for i, v in c.vision.items()},
        c.factors.rename(index=rename),
        [rename[i] for i in c.train],
        [rename[i] for i in c.test],
    )
    said = []
    rows = visibility_check(
        [c, twin], _probe(), VisibilitySettings(bootstrap=200), progress=said.append
    )
    a, b = (rows[rows["corpus"] == n].reset_index(drop=True) for n in ("toy", "toy_null"))
    pd.testing.assert_frame_equal(
        a.drop(columns=["row_id", "corpus"]), b.drop(columns=["row_id", "corpus"])
    )
    assert b["row_id"].str.startswith("toy_null|").all() and rows["row_id"].is_unique
    assert any("toy_null: the vision features, factors and split of toy" in m for m in said)
    assert sum("probe on V" in m for m in said) == 6  # fitted once: 3 factors x 2 probes


def test_a_factor_level_held_out_of_the_train_rows_is_not_checked():
    c = _corpus()
    factors = c.factors.copy()
    factors.loc[list(c.test), "size"] = "medium-sized"  # a level no train row has
    held = VisibilityCorpus(c.name, c.vision, factors, c.train, c.test)
    rows = visibility_check([held], _probe(), VisibilitySettings(bootstrap=200))
    assert "size" not in set(rows["factor"]) and {"colour", "texture"} <= set(rows["factor"])


def test_the_2_layer_probe_reads_the_gates_factors_only_and_a_compositional_class():
    """A class that is a union of (colour, texture) pairs, (colour + texture) mod 2 with the
    texture coded in one column's magnitude: the 2-layer probe (the probes stage's) reads it;
    it runs on the gate's factors only, and the gate reads the best probe."""
    from tacgen_lib.probes.settings import MLPGrid

    c = _corpus(n=400, seed=3)
    f = c.factors.copy()
    f["appearance"] = ((f["colour"].astype(int) + f["texture"].astype(int)) % 2).astype(str)
    c = VisibilityCorpus(c.name, c.vision, f, c.train, c.test)
    settings = VisibilitySettings(
        gammas=(1.0,), bootstrap=200, gate={"appearance": 0.9, "colour": 0.9}
    )
    grid = MLPGrid(widths=(32,), weight_decays=(0.01, 1.0), folds=3, max_iter=300)
    with threadpool_limits(1):
        rows = visibility_check([c], _probe(), settings, mlp=grid)
    probes = rows.groupby("factor")["probe"].apply(set).to_dict()
    assert probes["appearance"] == probes["colour"] == {"linear", "nonlinear", "mlp2"}
    assert probes["texture"] == probes["size"] == {"linear", "nonlinear"}  # not gated
    by = rows.set_index(["factor", "probe"])["score"]
    assert by["appearance", "mlp2"] > 0.9 > by["appearance", "linear"]
    gate = visibility_gate(rows, "toy", settings.gate)
    assert gate.scores["appearance"] == rows.loc[rows["factor"] == "appearance", "score"].max()
    assert gate.passed
    # without a grid, the check is the two probes of every factor
    with threadpool_limits(1):
        plain = visibility_check([c], _probe(), settings)
    assert set(plain["probe"]) == {"linear", "nonlinear"}


def test_a_gated_factor_with_a_one_row_class_gets_the_small_probe_fallback():
    """A class with one train row (a tiny corpus's colour): stratified CV cannot run, so the
    2-layer probe, like the kernel probe, is `fit_small_probe`'s fixed-C fit, not an error."""
    from tacgen_lib.probes.settings import MLPGrid

    c = _corpus(n=120, seed=5)
    f = c.factors.copy()
    f.loc[c.train[0], "colour"] = "7"  # a level of one train row
    c = VisibilityCorpus(c.name, c.vision, f, c.train, c.test)
    settings = VisibilitySettings(gammas=(1.0,), bootstrap=200, gate={"colour": 0.5})
    grid = MLPGrid(widths=(8,), weight_decays=(1.0,), folds=3, max_iter=50)
    rows = visibility_check([c], _probe(), settings, mlp=grid)
    colour = rows[rows["factor"] == "colour"].set_index("probe")
    assert set(colour.index) == {"linear", "nonlinear", "mlp2"}
    assert colour.loc["mlp2", "score"] == colour.loc["linear", "score"]
