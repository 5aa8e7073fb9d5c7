"""Probe-family orchestration (tacgen_lib.probes.protocol) and its report tables (tacgen_lib.report.probes), on synthetic data.

Two worlds: T carries the target (V+T must beat V, the controls must not), and T is unrelated to
the target (the null corpus: Delta must not be significantly > 0). References: scikit-learn
probes fitted directly on the same rows.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
import yaml
from probe_worlds import probe_settings, synthetic_family_rows
from sklearn.linear_model import Ridge
from sklearn.metrics import r2_score

from tacgen_lib.probes import compare as ps_compare
from tacgen_lib.probes import plan as ps_plan
from tacgen_lib.probes import protocol as ps_protocol
from tacgen_lib.probes import rows as ps_rows
from tacgen_lib.probes import settings as ps_settings
from tacgen_lib.report import probe_figures
from tacgen_lib.report import probes as report_probes
from tacgen_lib.report.write import figure_problems

VARIANTS = ["clip128", "histmatch"]
FUSIONS = ["concat", "mean"]


def settings(kind, seed=42, **kw):
    draws = dict(train_resamples=8, permutations=16, label_permutations=8, random_draws=4)
    grid = dict(lambdas=(0.1, 1.0, 10.0, 100.0), C=(0.1, 1.0), folds=3, bootstrap=400)
    return probe_settings(kind, **(grid | draws | kw), seed=seed)


def world(kind, *, carries, n_train=120, n_test=60, d_v=12, d_t=8, seed=0):
    """Synthetic family: a latent property z; V sees nothing of it; T sees it iff `carries`."""
    rng = np.random.default_rng(seed)
    n = n_train + n_test
    z = rng.standard_normal(n)
    v = rng.standard_normal((n, d_v))
    t = rng.standard_normal((n, d_t))
    if carries:
        t[:, :3] += 1.5 * z[:, None]
    if kind == "ridge":
        y = z + 0.3 * rng.standard_normal(n)
    else:
        y = np.where(z > 0, "hard", "soft").astype(object)
    rows = synthetic_family_rows(kind, y, n_train)

    def split(x):
        return x[:n_train], x[n_train:]

    tactile = {var: split(t + 0.05 * rng.standard_normal(t.shape)) for var in VARIANTS}
    aligned = {}
    for s in (42, 43):  # aligned projections: same dimension for V and T
        va = rng.standard_normal((n, 6))
        ta = rng.standard_normal((n, 6))
        if carries:
            ta[:, 0] += 2.0 * z
        aligned[s] = (*split(va), *split(ta))
    return rows, split(v), tactile, aligned


def run(kind, *, carries, seed=42, **kw):
    rows, vision, tactile, aligned = world(kind, carries=carries, **kw)
    return ps_protocol.run_family(
        "fam",
        rows,
        vision=vision,
        tactile=tactile,
        aligned=aligned,
        fusions=FUSIONS,
        heads_variant="clip128",
        settings=settings(kind, seed=seed),
        labels={"design": "paired", "null_corpus": not carries, "vision": "vit"},
        controls=True,
    )


@pytest.fixture(scope="module")
def ridge_signal():
    return run("ridge", carries=True)


@pytest.fixture(scope="module")
def logistic_signal():
    return run("logistic", carries=True)


# --------------------------------------------------------------------------- target + rows


def manifest_and_splits():
    ids = [f"c-{i:03d}" for i in range(12)]
    manifest = pd.DataFrame(
        {
            "sample_id": ids,
            "corpus": ["ctrl"] * 10 + ["other"] * 2,
            "mass": [0.5, 1.0, 2.0, 4.0, 0.5, 1.0, 2.0, np.nan, 1.0, 2.0, 3.0, 3.0],
            "hardness": [
                "soft",
                "hard",
                None,
                "hard",
                "soft",
                "hard",
                "soft",
                "hard",
                "soft",
                "hard",
                "soft",
                "hard",
            ],
            "shape": ["box", "ball"] * 6,
            "density": [600.0, 1200.0, 2400.0] * 4,
            "scale": [0.15] * 4 + [0.2] * 2 + [0.25] * 6,
        }
    )
    split = ["train", "val", "train", "train", "val", "train"] + ["test"] * 6
    return manifest, pd.DataFrame({"sample_id": ids, "corpus": manifest["corpus"], "split": split})


def test_target_values_log_mass_classes_and_missing():
    manifest, _ = manifest_and_splits()
    np.testing.assert_allclose(
        ps_rows.target_values(manifest, "log_mass", "ridge")[:4], np.log([0.5, 1.0, 2.0, 4.0])
    )
    assert np.isnan(ps_rows.target_values(manifest, "mass", "ridge")[7])
    hard = ps_rows.target_values(manifest, "hardness", "logistic")
    assert hard[0] == "soft" and hard[2] is None
    assert list(ps_rows.target_values(manifest, "density", "logistic")[:3]) == [
        "600.0",
        "1200.0",
        "2400.0",
    ]
    bad = manifest.assign(mass=manifest["mass"].where(manifest.index != 3, 0.0))
    with pytest.raises(ValueError, match="sample_id 'c-003' has mass <= 0"):
        ps_rows.target_values(bad, "log_mass", "ridge")
    with pytest.raises(ValueError, match="no column 'stiffness'"):
        ps_rows.target_values(manifest, "stiffness", "ridge")


def test_family_rows_train_includes_val_drops_unlabelled_and_builds_strata():
    manifest, splits = manifest_and_splits()
    rows = ps_rows.family_rows(
        manifest,
        splits,
        corpus="ctrl",
        target="mass",
        kind="ridge",
        strata=ps_rows.CONTROLLED_STRATA,
    )
    assert list(rows.train_ids) == ["c-000", "c-001", "c-002", "c-003", "c-004", "c-005"]
    assert list(rows.test_ids) == ["c-006", "c-008", "c-009"]  # c-007 has no mass
    assert rows.n_unlabelled == 1
    # test cells of one row each cannot be resampled within: they are pooled
    assert list(rows.strata_test) == ["pooled"] * 3
    assert (
        rows.strata_note
        == "shape x density x scale: 1 strata (3 test rows of cells with < 2 rows pooled)"
    )
    hard = ps_rows.family_rows(manifest, splits, corpus="ctrl", target="hardness", kind="logistic")
    assert "c-002" not in set(hard.train_ids) and hard.strata_test is None


def test_pool_strata_pools_cells_too_small_to_resample():
    labels = np.array(["a", "a", "a", "b", "b", "c", "d"], dtype=object)
    pooled, n = ps_rows.pool_strata(labels)
    assert list(pooled) == ["a", "a", "a", "b", "b", "pooled", "pooled"] and n == 2
    lone, n = ps_rows.pool_strata(np.array(["a", "a", "a", "b", "b", "c"], dtype=object))
    assert list(lone) == ["a", "a", "a", "pooled", "pooled", "pooled"] and n == 3
    same, n = ps_rows.pool_strata(np.array(["a", "a", "b", "b"], dtype=object))
    assert list(same) == ["a", "a", "b", "b"] and n == 0


def test_class_order_is_numeric_for_numbers():
    assert ps_rows.class_order(["5000.0", "500.0", "2000.0", "500.0"]) == [
        "500.0",
        "2000.0",
        "5000.0",
    ]
    assert ps_rows.class_order(["soft", "hard"]) == ["hard", "soft"]


def test_family_rows_refuses_unsplit_rows():
    manifest, splits = manifest_and_splits()
    with pytest.raises(ValueError, match="sample_id 'c-011' is not in the split edge"):
        ps_rows.family_rows(manifest, splits.iloc[:-1], corpus="other", target="mass", kind="ridge")


def test_force_bands_travel_with_the_results():
    rows, vision, tactile, aligned = world("ridge", carries=True)
    y = rows.y_test
    bands = pd.DataFrame({"force_p05": y - 0.5, "force_p95": y + 0.5})
    rows = ps_rows.FamilyRows(**{**rows.__dict__, "target": "force_p50", "bands_test": bands})
    res = ps_compare.compare(
        *vision, *tactile["clip128"], rows, "concat", settings("ridge"), controls=False
    )
    inside = (res.pred_vt >= y - 0.5) & (res.pred_vt <= y + 0.5)
    assert res.main["vt_in_band"] == pytest.approx(inside.mean())
    assert res.main["band_high_mean"] - res.main["band_low_mean"] == pytest.approx(1.0)


# --------------------------------------------------------------------------- plan


def test_plan_skips_same_dim_fusions_on_unequal_raw_dims_with_a_reason():
    plan = ps_plan.plan_comparisons(
        ["mean", "concat", "max"],
        heads_variant="a",
        variants=["a", "b"],
        align_seeds=[43, 42],
        dim_v_raw=768,
        dim_t_raw=192,
    )
    raw = [p for p in plan if p.input == "raw" and p.t_variant == "a"]
    assert [p.fusion for p in raw] == ["concat", "mean", "max"]
    assert raw[0].skip_reason is None and raw[0].controls
    assert "768" in raw[1].skip_reason and "192" in raw[1].skip_reason
    ablation = [p for p in plan if p.t_variant == "b"]
    assert [(p.fusion, p.controls) for p in ablation] == [("concat", False)]
    aligned = [p for p in plan if p.input == "aligned"]
    assert [(p.align_seed, p.fusion) for p in aligned][:3] == [
        (42, "mean"),
        (42, "concat"),
        (42, "max"),
    ]
    assert [p.fusion for p in aligned if p.controls] == ["concat", "concat"]
    assert all(p.skip_reason is None for p in aligned)
    capped = ps_plan.plan_comparisons(
        ["concat"],
        heads_variant="a",
        variants=["a"],
        align_seeds=[43, 42],
        dim_v_raw=8,
        dim_t_raw=8,
        control_align_seeds=1,
    )
    assert [(p.input, p.align_seed) for p in capped if p.controls] == [
        ("raw", None),
        ("aligned", 42),
    ]
    equal = ps_plan.plan_comparisons(
        ["concat", "mean"],
        heads_variant="a",
        variants=["a"],
        align_seeds=[],
        dim_v_raw=8,
        dim_t_raw=8,
    )
    assert all(p.skip_reason is None for p in equal)


def test_families_compare_like_with_like_and_repeat_no_rows():
    """Aligned rows only where V is ViT (the heads' input); two families whose rows would be
    identical are refused; the default config passes."""
    assert ps_settings.has_aligned_rows("vit") and not ps_settings.has_aligned_rows("pixel")
    fam = {"corpus": "c", "heads_from": "p", "target": "mass", "kind": "ridge"}
    ps_settings.check_families(
        {"mass": {**fam, "vision": "pixel"}, "mass_vit": {**fam, "vision": "vit"}}
    )
    with pytest.raises(ValueError, match="'b' and 'a' would produce identical raw rows"):
        ps_settings.check_families({"b": {**fam, "vision": "vit"}, "a": {**fam, "vision": "vit"}})
    heads = {**fam, "heads_from": "q", "vision": "vit"}  # other heads: same raw rows
    with pytest.raises(ValueError, match="identical raw rows"):
        ps_settings.check_families({"a": {**fam, "vision": "vit"}, "b": heads})
    root = Path(__file__).resolve().parents[2]
    families = yaml.safe_load((root / "config/config.yaml").read_text())["probes"]["families"]
    ps_settings.check_families(families)
    pixel = [f for f, spec in families.items() if spec["vision"] == "pixel"]
    assert pixel and all(
        any(
            g["vision"] == "vit" and g["target"] == families[f]["target"] for g in families.values()
        )
        for f in pixel
    )  # every pixel-V family's aligned results live in a ViT-V family of the same target


def test_baseline_score_is_the_train_mean_or_majority_class():
    from sklearn.dummy import DummyClassifier, DummyRegressor

    rng = np.random.default_rng(0)
    y_tr, y_te = rng.normal(3.0, 1.0, 40), rng.normal(2.0, 1.0, 20)
    ref = r2_score(y_te, DummyRegressor().fit(np.zeros((40, 1)), y_tr).predict(np.zeros((20, 1))))
    assert ps_rows.baseline_score(y_tr, y_te, "r2") == pytest.approx(ref)
    assert ps_rows.baseline_score(y_tr, y_te, "r2") < 0  # a shifted test mean: below zero
    c_tr = np.array(["soft"] * 7 + ["hard"] * 5, dtype=object)
    c_te = np.array(["soft", "hard", "hard", "soft", "soft"], dtype=object)
    dummy = DummyClassifier(strategy="most_frequent").fit(np.zeros((12, 1)), c_tr)
    assert (
        ps_rows.baseline_score(c_tr, c_te, "accuracy")
        == (dummy.predict(np.zeros((5, 1))) == c_te).mean()
    )


def test_visible_ceiling_recovers_mass_from_shape_and_scale_when_density_is_constant():
    """mass = density x c_shape x scale^3: with one density the shape-only ceiling is ~1 on
    an unseen scale (extrapolation in scale^3), and with random density it stays below 1."""
    rng = np.random.default_rng(1)
    n = 90
    shape = rng.choice(["cube", "sphere", "capsule"], n)
    scale = np.tile([0.15, 0.2, 0.25], n // 3)
    c = pd.Series(shape).map({"cube": 1.0, "sphere": 0.52, "capsule": 0.3}).to_numpy()
    for density, lo, hi in (
        (np.full(n, 1000.0), 0.999, 1.0),
        (rng.choice([500.0, 5000.0], n), -1, 0.9),
    ):
        manifest = pd.DataFrame(
            {
                "sample_id": [f"s{i:03d}" for i in range(n)],
                "corpus": "ctrl",
                "shape": shape,
                "scale": scale,
                "density": density,
                "mass": density * c * scale**3,
            }
        )
        splits = manifest[["sample_id", "corpus"]].assign(
            split=np.where(scale == 0.25, "test", "train")
        )
        rows = ps_rows.family_rows(manifest, splits, corpus="ctrl", target="mass", kind="ridge")
        got = ps_rows.visible_score(rows, settings("ridge"))
        assert lo <= got <= hi, got


# --------------------------------------------------------------------------- T carries y


def test_signal_world_concat_beats_v_and_controls_do_not(ridge_signal):
    rows = ridge_signal.rows.set_index("row_id")
    assert rows.index.is_unique
    main = rows.loc["fam|raw|t~clip128|concat|a~-|s~42|none"]
    assert main["status"] == "ok" and main["controls"] == "run"
    assert main["delta"] > 0.3 and main["ci_low"] > 0 and main["p_gt0"] == 1.0
    assert main["criterion_met"] is True or main["criterion_met"] == True  # noqa: E712
    ctrl = rows.loc["fam|raw|t~clip128|concat|a~-|s~42|tactile_permutation"]
    assert ctrl["delta"] == pytest.approx(main["delta_ctrl"])
    assert ctrl["delta"] < main["delta"] - 0.2
    for control in ("label_permutation", "random_features"):
        assert rows.loc[f"fam|raw|t~clip128|concat|a~-|s~42|{control}", "delta"] < 0.1
    resample = rows.loc["fam|raw|t~clip128|concat|a~-|s~42|train_resample"]
    assert resample["ci_low"] > 0 and resample["n_resamples"] == 8
    aligned = rows.loc["fam|aligned|t~clip128|mean|a~43|s~42|none"]
    assert aligned["delta"] > 0 and aligned["controls"] == "not run"
    assert pd.isna(aligned["criterion_met"]) and np.isnan(aligned["delta_ctrl"])


def test_main_scores_equal_sklearn_on_the_same_rows(ridge_signal):
    """The orchestration feeds the right rows: V and V+T scores equal sklearn Ridge refits."""
    rows, vision, tactile, _ = world("ridge", carries=True)
    main = ridge_signal.rows.set_index("row_id").loc["fam|raw|t~histmatch|concat|a~-|s~42|none"]
    v_ref = Ridge(alpha=main["v_reg"]).fit(vision[0], rows.y_train).predict(vision[1])
    x_tr = np.hstack([vision[0], tactile["histmatch"][0]])
    x_te = np.hstack([vision[1], tactile["histmatch"][1]])
    vt_ref = Ridge(alpha=main["vt_reg"]).fit(x_tr, rows.y_train).predict(x_te)
    assert main["v_score"] == pytest.approx(r2_score(rows.y_test, v_ref), abs=1e-9)
    assert main["vt_score"] == pytest.approx(r2_score(rows.y_test, vt_ref), abs=1e-9)
    assert main["n_train"] == 120 and main["n_test"] == 60 and main["dim_vt"] == 20


def test_sweep_marks_the_cv_choice_and_matches_the_main_row(ridge_signal):
    sweep = ridge_signal.sweep
    key = "fam|raw|t~clip128|concat|a~-|s~42|none"
    main = ridge_signal.rows.set_index("row_id").loc[key]
    mine = sweep.loc[sweep["comparison"] == key]
    assert list(mine["reg"]) == [0.1, 1.0, 10.0, 100.0]
    chosen = mine.loc[mine["selected_vt"]]
    assert len(chosen) == 1 and chosen["reg"].iloc[0] == main["vt_reg"]
    assert chosen["test_vt"].iloc[0] == pytest.approx(main["vt_score"], abs=1e-9)


def test_logistic_family_confusion_counts_and_signal(logistic_signal):
    rows = logistic_signal.rows.set_index("row_id")
    main = rows.loc["fam|raw|t~clip128|concat|a~-|s~42|none"]
    assert main["metric"] == "accuracy" and main["reg_name"] == "C"
    assert main["delta"] > 0.2 and main["ci_low"] > 0 and bool(main["converged"])
    conf = logistic_signal.confusion
    one = conf.loc[conf["comparison"] == "fam|raw|t~clip128|concat|a~-|s~42|none"]
    for model, score in (("V", main["v_score"]), ("V+T", main["vt_score"])):
        m = one.loc[one["model"] == model]
        assert m["count"].sum() == 60 and len(m) == 4
        assert m.loc[m["true"] == m["pred"], "count"].sum() / 60 == pytest.approx(score)


def test_unfittable_logistic_comparison_is_a_failed_row_not_a_crash():
    rows, vision, tactile, aligned = world("logistic", carries=True)
    y = rows.y_train.copy()
    y[:] = "soft"
    y[0] = "hard"  # one training row of class "hard": stratified CV is impossible
    rows = ps_rows.FamilyRows(**{**rows.__dict__, "y_train": y})
    res = ps_protocol.run_family(
        "fam",
        rows,
        vision=vision,
        tactile=tactile,
        aligned=aligned,
        fusions=["concat"],
        heads_variant="clip128",
        settings=settings("logistic"),
        controls=True,
    )
    assert set(res.rows["status"]) == {"failed"}
    assert res.rows["notes"].str.contains("has 1 training row").all()
    assert res.confusion.empty and list(res.confusion.columns) == list(
        ps_protocol.CONFUSION_COLUMNS
    )


def test_a_failing_control_is_its_own_failed_row():
    """Bootstrap resamples of 8 training rows often hold one class: that control fails alone."""
    rows, vision, tactile, _ = world("logistic", carries=True, n_train=8, n_test=20)
    y = np.array(["soft"] * 5 + ["hard"] * 3, dtype=object)
    rows = ps_rows.FamilyRows(**{**rows.__dict__, "y_train": y})
    res = ps_compare.compare(
        *vision,
        *tactile["clip128"],
        rows,
        "concat",
        settings("logistic", folds=2, train_resamples=40),
        controls=True,
    )
    status = {c["control"]: c["status"] for c in res.controls}
    assert status == {
        "train_resample": "failed",
        "tactile_permutation": "ok",
        "label_permutation": "ok",
        "random_features": "ok",
    }
    failed = res.controls[0]
    assert "at least 2 classes" in failed["notes"] or "one class" in failed["notes"]
    assert res.main["status"] == "ok" and res.main["criterion_met"] is not None


def test_family_run_is_deterministic(ridge_signal):
    again = run("ridge", carries=True)
    pd.testing.assert_frame_equal(again.rows, ridge_signal.rows)
    pd.testing.assert_frame_equal(again.sweep, ridge_signal.sweep)


# --------------------------------------------------------------------------- null world


@pytest.mark.parametrize("kind", ["ridge", "logistic"])
def test_null_world_delta_is_not_significantly_positive(kind):
    """T unrelated to y (the null corpus): no comparison meets the criterion, and the controlled
    comparisons' CIs cover 0."""
    res = run(kind, carries=False, seed=7)
    main = res.rows.loc[(res.rows["control"] == "none") & (res.rows["status"] == "ok")]
    assert len(main) == 6  # raw concat (mean: skipped, 12 vs 8 dims); ablation; aligned 2 x 2
    assert not main["criterion_met"].fillna(False).astype(bool).any()
    ctl = main.loc[main["controls"] == "run"]
    # ridge: raw + both alignment seeds; logistic: raw + the first alignment seed
    assert len(ctl) == (3 if kind == "ridge" else 2) and (ctl["ci_low"] <= 0).all()
    assert (main["p_gt0"] < 0.975).all()


# --------------------------------------------------------------------------- report


def summary_of(*results):
    return pd.concat([r.rows for r in results], ignore_index=True)


def test_report_tables_and_figures_from_a_summary(ridge_signal, logistic_signal):
    null = run("ridge", carries=False)
    null_rows = null.rows.assign(
        family="fam_null", row_id=null.rows["row_id"].str.replace("fam|", "fam_null|")
    )
    logistic = logistic_signal.rows.assign(
        family="hard",
        design="controlled",
        vision="pixel",
        row_id=logistic_signal.rows["row_id"].str.replace("fam|", "hard|"),
    )
    summary = pd.concat([ridge_signal.rows, null_rows, logistic], ignore_index=True)
    paired = report_probes.paired_table(summary)
    assert set(paired["family"]) == {"fam"}  # the null sibling sits beside, not below
    first = paired.iloc[0]
    assert first["input"] == "aligned" or first["input"] == "raw"
    assert paired["null: Δ [95% CI]"].str.len().gt(0).all()
    controlled = report_probes.controlled_table(summary)
    # the raw same-dimension fusions planned as skipped are left out, and said once below
    assert set(controlled["family"]) == {"hard"} and len(controlled) == 5
    (note,) = report_probes.skipped_note(summary, controlled=True)
    assert note.startswith("1 comparison not run and not listed")
    seeds = report_probes.align_seed_table(summary)
    row = seeds.loc[(seeds["family"] == "fam") & (seeds["fusion"] == "concat")].iloc[0]
    assert row["align seeds"] == "42, 43" and row["criterion met"] == "2/2"
    variants = report_probes.variant_table(summary)
    assert {"V alone", "clip128", "histmatch"} <= set(variants.columns)
    controls = report_probes.controls_table(summary)
    assert set(controls["control"]) == set(ps_compare.CONTROLS)
    sweep = report_probes.sweep_table(
        pd.concat([ridge_signal.sweep, logistic_signal.sweep.assign(family="hard")]), summary
    )
    assert {"lambda=0.1", "lambda=100", "C=0.1", "C=1"} <= set(sweep.columns)
    assert sweep.filter(like="lambda=").apply(lambda c: c.str.endswith("*")).to_numpy().any()
    assert len(report_probes.fusions_frame()) == 5  # concat, mean, max, two weighted sums
    shown = summary.loc[
        (summary["control"] == "none")
        & (summary["status"] == "ok")
        & (summary["t_variant"] == summary["heads_variant"])
    ]
    families = probe_figures.forest_families(summary)
    assert set(families) == set(shown["family"])  # one figure per family
    for fam in families:
        fig = probe_figures.forest_plot(summary, fam)
        assert not figure_problems(fig)  # fits the viewer, text >= 8 pt
        (ax,) = fig.axes
        assert ax.get_title().startswith(f"{fam} (")
        labels = [t.get_text() for t in ax.get_yticklabels()]
        assert len(labels) == (shown["family"] == fam).sum()
        if fam == "fam_null":
            assert "raw / concat  a~- s~42" in labels
        plt.close(fig)
    conf = logistic_signal.confusion.assign(family="hard")
    figs = probe_figures.confusion_figures(conf)
    assert list(figs) == ["hard"]
    assert sum(ax.has_data() for ax in figs["hard"].axes) == 2 * 3  # raw + two seeds, V and V+T
    assert not figure_problems(figs["hard"])
