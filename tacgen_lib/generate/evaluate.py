"""Judging generated touch by what it adds to the probes (paper: Delta R^2_gen), with controls.

This module owns the evaluation of one generator (corpus x seed) over all its sampling cells
(`evaluate_generator`), and the probes no generator changes (`fit_baselines`: V alone, V +
T_real and the nonlinear V baseline, fitted once per corpus and shared by every seed through
the baselines edge, `baselines_frame` / `baselines_from_frame`). The probes are the probes
stage's own (`tacgen_lib.probes.fit.fit_probe` on the same `family_rows` train/test rows,
`fixed_test_bootstrap` for the CIs), not a fork. Per target:

- ``v``: V alone (the reference of every Delta); fitted once per corpus (`fit_baselines`);
- ``t_real``: V + T_real, the protocol-matched real-touch point (ViT tactile features);
- ``t_gen``: V + T_gen of one sampling cell;
- ``t_gen_shuffled``: V + T_gen where row i gets the vector generated for another row
  (a seeded permutation of all rows of the corpus: the pairing is broken, the marginal kept);
- ``v_nonlinear``: V + phi(V), phi an RBF Nystroem map of V with as many components as T has
  dimensions, gamma (a multiple of the median heuristic) and the regulariser chosen by CV on
  the train rows only (Nystroem drawn with the probe seed: it does not depend on the generator).
  T_gen is a function of V, so a gain of V + T_gen over linear V may be nonlinearity, not
  touch; ``delta_vs_nonlinear`` = score(V + x) - score(V + phi(V)) says.
- ``t_ridge`` / ``t_ridge_residual``: V + the simplest generator's output, ridge V->T fitted on
  the generator's own train rows (its conditional mean; the mean plus a sampled train
  residual: `tacgen_lib.generate.ridge_generator`). A diffusion generator that does no better than it
  has learnt nothing a linear map does not give; ``delta_vs_ridge`` = score(V + T_gen) -
  score(V + T_ridge) on the ``t_gen`` rows says, and each ridge row carries its own fidelity.

Every Delta is paired on the same test rows with the same 5,000 fixed-test resamples (drawn
once per target and shared by every bootstrap of that target: identical to drawing them per
call with the same seed).

Regularisation of the per-cell probes (``t_gen``, ``t_gen_shuffled``). Ridge chooses lambda by
CV in every cell (closed form over the grid: costs next to nothing). The logistic probe's CV
(folds x C lbfgs fits) dominated the stage when repeated per cell, so its C is chosen ONCE per
target and input kind: by CV on the train rows of the *reference cell* (the report's headline
cell), then reused for that input kind in every other cell, refitted on the same train rows
(`probes.logistic.FixedLogistic`, the same lbfgs settings as the CV's final fit). The reference
cell's rows are therefore exactly what per-cell CV gives; the other cells differ only where
their own CV would have picked another C. Columns ``reg`` and ``reg_source`` (``cv`` or
``reference cell``) record it per row. No test row is used to choose anything.
Fidelity of each cell on the test rows (`fidelity`): matched-pair cosine (gen_i vs real_i)
against the off-diagonal mean, a pairing-permutation check (one-sided p of the matched mean
cosine against `permutations` re-pairings) and the Frechet distance between generated and real
test latents, beside the Frechet distance between the real train and real test latents (the
distance two real samples of these sizes already have). Cosines are taken after centring on
the real train mean (ViT features share a large common component that makes every cosine
near 1).

The fidelity measures live in `fidelity`, the baselines fitted once per corpus in `baselines`;
this module evaluates one generator's cells against them (`evaluate_generator`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
import pandas as pd

from tacgen_lib.generate.baselines import BASELINE_INPUTS, Baselines, TargetSpec
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.fidelity import (
    PERMUTATION_COLUMNS,
    centred_gaps,
    fidelity,
    gap_interval,
)
from tacgen_lib.generate.ridge_generator import RIDGE_ALPHAS, ridge_generate
from tacgen_lib.generate.sampling_cells import RIDGE_INPUTS
from tacgen_lib.probes.bootstrap import (
    fixed_test_bootstrap,
    percentile_interval,
    resample_indices,
)
from tacgen_lib.probes.fit import FittedProbe, fit_probe
from tacgen_lib.probes.logistic import FixedLogistic
from tacgen_lib.probes.rows import FamilyRows, baseline_score
from tacgen_lib.probes.settings import ProbeSettings

#: What is added to V in a summary row.
INPUTS = ("t_real", "t_gen", "t_gen_shuffled", "v_nonlinear", *RIDGE_INPUTS)


def shuffled_rows(n: int, seed: int) -> np.ndarray:
    """A seeded permutation of n rows with no fixed point when n > 1 (every pairing broken)."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(n)
    if n > 1:
        fixed = perm == np.arange(n)
        perm[fixed] = np.roll(perm[fixed], 1)  # a cycle among the fixed points
        if (perm == np.arange(n)).any():  # a single fixed point left: swap with a neighbour
            i = int(np.flatnonzero(perm == np.arange(n))[0])
            j = (i + 1) % n
            perm[i], perm[j] = perm[j], perm[i]
    return perm


#: ``reg_source`` of a probe whose regulariser was chosen by its own CV / taken from the
#: reference cell's CV of the same input kind (logistic t_gen and t_gen_shuffled only).
REG_CV, REG_REFERENCE = "cv", "reference cell"


def _row(
    base: dict, inp: str, boot: dict, vs_nl: dict | None, vs_ridge: dict | None = None
) -> dict:
    return {
        **base,
        "input": inp,
        "score": boot["vt_score"],
        "v_score": boot["v_score"],
        "delta": boot["delta"],
        "ci_low": boot["ci_low"],
        "ci_high": boot["ci_high"],
        "p_gt0": boot["p_gt0"],
        "delta_vs_nonlinear": np.nan if vs_nl is None else vs_nl["delta"],
        "ci_low_vs_nonlinear": np.nan if vs_nl is None else vs_nl["ci_low"],
        "ci_high_vs_nonlinear": np.nan if vs_nl is None else vs_nl["ci_high"],
        "delta_vs_ridge": np.nan if vs_ridge is None else vs_ridge["delta"],
        "ci_low_vs_ridge": np.nan if vs_ridge is None else vs_ridge["ci_low"],
        "ci_high_vs_ridge": np.nan if vs_ridge is None else vs_ridge["ci_high"],
        # the family-wise interval of a generated-touch row (`family_interval`); NaN elsewhere
        "ci_low_fw": boot.get("ci_low_fw", np.nan),
        "ci_high_fw": boot.get("ci_high_fw", np.nan),
        "ci_low_fw_vs_ridge": np.nan if vs_ridge is None else vs_ridge.get("ci_low_fw", np.nan),
        "ci_high_fw_vs_ridge": np.nan if vs_ridge is None else vs_ridge.get("ci_high_fw", np.nan),
    }


#: The pairing-gap columns of a ``t_gen`` row (`pairing_gap_columns`).
GAP_COLUMNS = (
    "pairing_gap",
    "pairing_gap_ci_low",
    "pairing_gap_ci_high",
    *(f"gap_vs_{a}{c}" for a in ("ridge", "ridge_residual") for c in ("", "_ci_low", "_ci_high")),
)


def pairing_gap_columns(
    gen_gaps: np.ndarray, ridge_gaps: Mapping[str, np.ndarray], resamples: np.ndarray
) -> dict[str, float]:
    """The diffusion samples' pairing gap with real touch (`fidelity.pairing_gaps`: matched
    minus off-diagonal cosine, per test row) with its CI over the target's fixed-test
    resamples, and its paired differences from the ridge generator's mean (``t_ridge``) and
    ridge + a sampled residual (``t_ridge_residual``) on the same rows with theirs
    (`fidelity.gap_interval`): `GAP_COLUMNS`."""
    out = dict(zip(GAP_COLUMNS[:3], gap_interval(gen_gaps, resamples), strict=True))
    for arm, inp in (("ridge", "t_ridge"), ("ridge_residual", "t_ridge_residual")):
        d, lo, hi = gap_interval(gen_gaps - ridge_gaps[inp], resamples)
        out.update({f"gap_vs_{arm}": d, f"gap_vs_{arm}_ci_low": lo, f"gap_vs_{arm}_ci_high": hi})
    return out


#: The family-wise error rate of the generated-touch rows a page compares (two-sided).
FAMILY_ALPHA = 0.05


def family_interval(deltas: np.ndarray, size: int) -> tuple[float, float]:
    """The Bonferroni interval of one of `size` compared bootstrap differences: the central
    1 - `FAMILY_ALPHA` / size percentile interval (`bootstrap.percentile_interval`). All
    `size` intervals hold together with probability at least 1 - `FAMILY_ALPHA`; at size 1 it
    is the 95 % CI. Its lower bound above 0 is a gain read family-wise, the first step of
    Holm's procedure (`probes.multiplicity.holm`) on the same comparisons."""
    if size < 1:
        raise ValueError(f"family_interval: family size must be at least 1, got {size}")
    return percentile_interval(deltas, confidence_level=1.0 - FAMILY_ALPHA / size)


def _cell_order(
    cells: Sequence[tuple[str, str, str]], reference: tuple[str, str, str] | None
) -> list[tuple[str, str, str]]:
    """The cells with the reference cell first (its CV fixes the logistic C of the others)."""
    cells = list(cells)
    if reference is None or not cells:
        return cells
    ref = tuple(str(x) for x in reference)
    if ref not in cells:
        raise ValueError(f"evaluate_generator: reference cell {ref} is not among the cells {cells}")
    return [ref] + [c for c in cells if c != ref]


def evaluate_generator(
    targets: Sequence[TargetSpec],
    *,
    corpus: str,
    seed: int,
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    t_gen: Mapping[tuple[str, str, str], Mapping[str, np.ndarray]],
    baselines: Mapping[str, Baselines],
    permutations: int,
    generator_train_ids: Sequence[str],
    reference: tuple[str, str, str] | None = None,
    labels: Mapping[str, object] | None = None,
    family: int = 1,
    progress: Callable[[str], None] | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Summary rows (one per target x cell x input) and permutation draws of one generator.

    vision, t_real: sample_id -> vector, for every row of the corpus (dicts keep this
    function free of edge I/O); t_gen: (sampler, guidance, steps) -> sample_id -> vector;
    baselines: target -> its `fit_baselines` (V, V + T_real, nonlinear V: shared by seeds).
    `generator_train_ids`: the rows the generator learnt from; the ridge V->T generator
    (`tacgen_lib.generate.ridge_generator`, its residual draw seeded by `seed`) is fitted on them, and
    its two arms are evaluated beside every cell: rows ``t_ridge`` and ``t_ridge_residual``,
    each with its own fidelity, and ``delta_vs_ridge`` = score(V + T_gen) - score(V + T_ridge)
    on the ``t_gen`` rows. `reference`: the cell whose CV chooses the logistic C of every cell
    (module docstring; default: the first cell). `family`: how many generated-touch rows the
    page compares (`sampling_cells.family_size`); each generated row (``t_gen``, ``t_gen_shuffled``, the
    ridge arms) also carries its family-wise interval, ``ci_low_fw`` / ``ci_high_fw``
    (`family_interval`), from the same resamples as its CI.
    """
    say = progress or (lambda _m: None)
    ridge = ridge_generate(vision, t_real, generator_train_ids, seed=seed, alphas=RIDGE_ALPHAS)
    say(f"ridge V->T generator: alpha {ridge.alpha:g} by leave-one-out on {ridge.n_train} rows")
    ridge_sources = dict(zip(RIDGE_INPUTS, (ridge.mean, ridge.residual), strict=True))

    all_ids = np.array(sorted(vision), dtype=object)
    perm = shuffled_rows(len(all_ids), seed)
    shuffled_of = dict(zip(all_ids, all_ids[perm], strict=True))
    cells = _cell_order(list(t_gen), reference)
    out_rows: list[dict] = []
    perm_rows: list[dict] = []
    fid_cache: dict[tuple, dict] = {}
    for spec in targets:
        rows, ps = spec.rows, spec.settings
        v_tr, v_te = feature_block(vision, rows.train_ids), feature_block(vision, rows.test_ids)
        t_tr, t_te = feature_block(t_real, rows.train_ids), feature_block(t_real, rows.test_ids)
        # one draw of the 5,000 test resamples, shared by every bootstrap of this target
        resamples = resample_indices(
            len(rows.y_test), ps.bootstrap, ps.seed, strata=rows.strata_test
        )

        def fit(
            x_tr: np.ndarray, x_te: np.ndarray, ps: ProbeSettings = ps, rows: FamilyRows = rows
        ) -> FittedProbe:
            return fit_probe(
                x_tr, rows.y_train, x_te, ps, train_ids=rows.train_ids, test_ids=rows.test_ids
            )

        def boot(
            pred_a: np.ndarray,
            pred_b: np.ndarray,
            ps: ProbeSettings = ps,
            rows: FamilyRows = rows,
            resamples: np.ndarray = resamples,
            generated: bool = False,
        ) -> dict:
            out = fixed_test_bootstrap(
                rows.y_test,
                pred_a,
                pred_b,
                ps.metric,
                n_resamples=ps.bootstrap,
                seed=ps.seed,
                indices=resamples,
                sample_ids=rows.test_ids,
                return_distribution=generated,
            )
            if generated:
                out["ci_low_fw"], out["ci_high_fw"] = family_interval(out.pop("deltas"), family)
            return out

        chosen: dict[str, float] = {}  # input kind -> C chosen on the reference cell

        def fit_cell(
            inp: str,
            x_tr: np.ndarray,
            x_te: np.ndarray,
            ps: ProbeSettings = ps,
            rows: FamilyRows = rows,
            chosen: dict[str, float] = chosen,
        ) -> tuple[np.ndarray, float, str]:
            """(test predictions, regulariser, its source) of one cell's V + x probe."""
            if ps.kind == "logistic" and inp in chosen:
                # lbfgs from max_iter = the cap at once: the iterates do not depend on max_iter,
                # so a fit that converges gives the probe's own fit without its restarts
                # (fit_logistic_once doubles max_iter from 200 and starts again from zero)
                cap = FixedLogistic.max_iter_cap
                fixed = FixedLogistic(chosen[inp], max_iter=cap, max_iter_cap=cap)
                pred = np.asarray(fixed.fit_predict(x_tr, rows.y_train, x_te), dtype=object)
                return pred, chosen[inp], REG_REFERENCE
            probe = fit(x_tr, x_te)
            if ps.kind == "logistic":
                chosen[inp] = float(probe.reg)
            return probe.pred_test, float(probe.reg), REG_CV

        if spec.name not in baselines:
            raise ValueError(f"evaluate_generator: no baselines for target {spec.name!r}")
        bl = baselines[spec.name]
        p_v, p_real, p_nl = (np.asarray(bl.pred[k]) for k in BASELINE_INPUTS)
        if not len(p_v) == len(p_real) == len(p_nl) == rows.n_test:
            raise ValueError(
                f"evaluate_generator: {spec.name} baselines are not on its {rows.n_test} test rows"
            )
        gamma = bl.gamma
        base = {
            "corpus": corpus,
            "target": spec.name,
            "kind": ps.kind,
            "metric": ps.metric,
            "seed": int(seed),
            "probe_seed": ps.seed,
            "n_train": rows.n_train,
            "n_test": rows.n_test,
            # the constant predictor's test score (train mean / majority class): a V score
            # below it is a probe failing, not vision lacking the label
            "baseline_score": baseline_score(rows.y_train, rows.y_test, ps.metric),
            "nonlinear_gamma": gamma,
            **(labels or {}),
        }
        # the rows every cell repeats (they do not depend on the cell): bootstrapped once
        real_row = _row({}, "t_real", boot(p_v, p_real), boot(p_nl, p_real))
        nl_row = _row({}, "v_nonlinear", boot(p_v, p_nl), None)
        real_row.update(reg=bl.reg["t_real"], reg_source=REG_CV)
        nl_row.update(reg=bl.reg["v_nonlinear"], reg_source=REG_CV)
        # the ridge generator's arms: fitted and bootstrapped once, repeated in every cell
        ridge_rows, ridge_pred, ridge_gaps = [], {}, {}
        for inp, source in ridge_sources.items():
            r_tr, r_te = feature_block(source, rows.train_ids), feature_block(source, rows.test_ids)
            probe = fit(np.hstack([v_tr, r_tr]), np.hstack([v_te, r_te]))
            ridge_pred[inp] = probe.pred_test
            ridge_gaps[inp] = centred_gaps(r_te, t_te, t_tr)
            # the fidelity of these vectors on these rows: a target with the same test and
            # train rows (the centring) as another reuses it
            key = (inp, tuple(rows.test_ids), tuple(rows.train_ids))
            if key not in fid_cache:
                fid, _ = fidelity(r_te, t_te, t_tr, n_permutations=permutations, seed=seed)
                fid_cache[key] = fid
            r_fid = fid_cache[key]
            r_row = _row(
                {}, inp, boot(p_v, probe.pred_test, generated=True), boot(p_nl, probe.pred_test)
            )
            r_row.update(reg=float(probe.reg), reg_source=REG_CV, **r_fid)
            ridge_rows.append(r_row)
            say(
                f"{spec.name}: V+T_{inp.removeprefix('t_')} delta {r_row['delta']:+.3f} "
                f"[{r_row['ci_low']:+.3f}, {r_row['ci_high']:+.3f}], cos "
                f"{r_fid['cos_matched']:.3f} vs {r_fid['cos_offdiag']:.3f}"
            )
        say(
            f"{spec.name}: V {real_row['v_score']:.3f}, V+T_real delta {real_row['delta']:+.3f} "
            f"[{real_row['ci_low']:+.3f}, {real_row['ci_high']:+.3f}], nonlinear V delta "
            f"{nl_row['delta']:+.3f}"
        )
        for cell in cells:
            gen = t_gen[cell]
            sampler, guidance, steps = cell
            cell_base = {
                **base,
                "sampler": sampler,
                "guidance": float(guidance),
                "steps": int(steps),
            }
            g_tr, g_te = feature_block(gen, rows.train_ids), feature_block(gen, rows.test_ids)
            shuf = {i: gen[shuffled_of[i]] for i in vision}
            s_tr, s_te = feature_block(shuf, rows.train_ids), feature_block(shuf, rows.test_ids)
            p_gen, reg_gen, src_gen = fit_cell(
                "t_gen", np.hstack([v_tr, g_tr]), np.hstack([v_te, g_te])
            )
            p_shuf, reg_shuf, src_shuf = fit_cell(
                "t_gen_shuffled", np.hstack([v_tr, s_tr]), np.hstack([v_te, s_te])
            )
            key = (cell, tuple(rows.test_ids))
            if key not in fid_cache:
                fid, null = fidelity(g_te, t_te, t_tr, n_permutations=permutations, seed=seed)
                fid_cache[key] = fid
                label = f"{sampler}|w={guidance}|steps={steps}"
                perm_rows += [
                    {
                        "row_id": f"{corpus}|seed~{seed}|{label}|{spec.name}|perm~{k}",
                        "corpus": corpus,
                        "seed": int(seed),
                        "target": spec.name,
                        "sampler": sampler,
                        "guidance": float(guidance),
                        "steps": int(steps),
                        "permutation": k,
                        "statistic": float(s),
                        "observed": fid["cos_matched"],
                    }
                    for k, s in enumerate(null)
                ]
            fid = fid_cache[key]
            gen_row = _row(
                cell_base,
                "t_gen",
                boot(p_v, p_gen, generated=True),
                boot(p_nl, p_gen),
                boot(ridge_pred["t_ridge"], p_gen, generated=True),
            )
            shuf_row = _row(
                cell_base,
                "t_gen_shuffled",
                boot(p_v, p_shuf, generated=True),
                boot(p_nl, p_shuf),
            )
            gen_row.update(reg=reg_gen, reg_source=src_gen)
            gen_row.update(
                pairing_gap_columns(centred_gaps(g_te, t_te, t_tr), ridge_gaps, resamples)
            )
            shuf_row.update(reg=reg_shuf, reg_source=src_shuf)
            rows_cell = [{**cell_base, **real_row}, gen_row, shuf_row, {**cell_base, **nl_row}]
            for r in rows_cell:
                r.update(fid)
            rows_cell += [{**cell_base, **r} for r in ridge_rows]  # with their own fidelity
            for r in rows_cell:
                r["ridge_alpha"] = ridge.alpha
                r["row_id"] = (
                    f"{corpus}|{spec.name}|seed~{seed}|{sampler}|w={guidance}|"
                    f"steps={steps}|{r['input']}"
                )
            out_rows += rows_cell
            say(
                f"{spec.name} {sampler} w={guidance} steps={steps}: V+T_gen delta "
                f"{gen_row['delta']:+.3f} [{gen_row['ci_low']:+.3f}, {gen_row['ci_high']:+.3f}]"
                f" (C/lambda {reg_gen:g}, {src_gen}), vs nonlinear V "
                f"{gen_row['delta_vs_nonlinear']:+.3f}, vs ridge V->T "
                f"{gen_row['delta_vs_ridge']:+.3f}; shuffled {shuf_row['delta']:+.3f}; "
                f"cos {fid['cos_matched']:.3f} vs {fid['cos_offdiag']:.3f} "
                f"(p {fid['pairing_p']:.3f}), FD {fid['frechet']:.2f}"
            )
    perm_frame = pd.DataFrame(perm_rows, columns=list(PERMUTATION_COLUMNS))
    if perm_frame.empty:
        perm_frame = perm_frame.astype(
            {
                "row_id": "str",
                "corpus": "str",
                "target": "str",
                "sampler": "str",
                "seed": "int64",
                "steps": "int64",
                "permutation": "int64",
                "guidance": "float64",
                "statistic": "float64",
                "observed": "float64",
            }
        )
    return pd.DataFrame(out_rows), perm_frame
