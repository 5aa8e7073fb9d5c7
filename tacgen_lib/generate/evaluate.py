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
this module evaluates one generator's cells against them (`evaluate_generator`), with one
target's probes, bootstrap and family-wise interval from `evaluate_probes` and the edges' rows
from `evaluate_rows`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from tacgen_lib.generate.baselines import BASELINE_INPUTS, Baselines, TargetSpec
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.evaluate_probes import (
    REG_CV,
    TargetProbes,
    target_probes,
)
from tacgen_lib.generate.evaluate_rows import (
    permutation_frame,
    permutation_rows,
    summary_row,
    summary_row_id,
)
from tacgen_lib.generate.fidelity import centred_gaps, fidelity, gap_interval
from tacgen_lib.generate.ridge_generator import RIDGE_ALPHAS, ridge_generate
from tacgen_lib.generate.sampling_cells import RIDGE_INPUTS
from tacgen_lib.probes.rows import baseline_score

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


@dataclass
class _Generator:
    """What every target of one generator's evaluation shares: its corpus, seed and fidelity
    permutations, the corpus' rows (`vision`) with the row each is shuffled to, the ridge V->T
    generator's alpha and arms (`RIDGE_INPUTS` -> sample_id -> vector), the fidelity computed
    so far (a target on the same rows reuses it) and the progress line."""

    corpus: str
    seed: int
    permutations: int
    vision: Mapping[str, np.ndarray]
    shuffled_of: dict
    ridge_alpha: float
    ridge_sources: dict[str, Mapping[str, np.ndarray]]
    say: Callable[[str], None]
    fid_cache: dict[tuple, dict] = field(default_factory=dict)


@dataclass
class _Repeated:
    """What every cell of one target repeats: the target's columns, V's and nonlinear V's test
    predictions, the V + T_real and nonlinear V rows, and the ridge V->T generator's rows, test
    predictions and pairing gaps (per arm)."""

    base: dict
    p_v: np.ndarray
    p_nl: np.ndarray
    real_row: dict
    nl_row: dict
    ridge_rows: list[dict]
    ridge_pred: dict[str, np.ndarray]
    ridge_gaps: dict[str, np.ndarray]


def _target_base(
    g: _Generator, tg: TargetProbes, gamma: float, labels: Mapping[str, object] | None
) -> dict:
    """The columns every summary row of one target carries."""
    rows, ps = tg.rows, tg.ps
    return {
        "corpus": g.corpus,
        "target": tg.name,
        "kind": ps.kind,
        "metric": ps.metric,
        "seed": int(g.seed),
        "probe_seed": ps.seed,
        "n_train": rows.n_train,
        "n_test": rows.n_test,
        # the constant predictor's test score (train mean / majority class): a V score
        # below it is a probe failing, not vision lacking the label
        "baseline_score": baseline_score(rows.y_train, rows.y_test, ps.metric),
        "nonlinear_gamma": gamma,
        **(labels or {}),
    }


def _ridge_arms(
    g: _Generator, tg: TargetProbes, p_v: np.ndarray, p_nl: np.ndarray
) -> tuple[list[dict], dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The ridge V->T generator's arms on one target, fitted and bootstrapped once (every cell
    repeats them): their rows (each with its own fidelity), test predictions and pairing gaps."""
    rows = tg.rows
    ridge_rows, ridge_pred, ridge_gaps = [], {}, {}
    for inp, source in g.ridge_sources.items():
        r_tr, r_te = feature_block(source, rows.train_ids), feature_block(source, rows.test_ids)
        probe = tg.fit(np.hstack([tg.v_tr, r_tr]), np.hstack([tg.v_te, r_te]))
        ridge_pred[inp] = probe.pred_test
        ridge_gaps[inp] = centred_gaps(r_te, tg.t_te, tg.t_tr)
        # the fidelity of these vectors on these rows: a target with the same test and
        # train rows (the centring) as another reuses it
        key = (inp, tuple(rows.test_ids), tuple(rows.train_ids))
        if key not in g.fid_cache:
            fid, _ = fidelity(r_te, tg.t_te, tg.t_tr, n_permutations=g.permutations, seed=g.seed)
            g.fid_cache[key] = fid
        r_fid = g.fid_cache[key]
        r_row = summary_row(
            {}, inp, tg.boot(p_v, probe.pred_test, generated=True), tg.boot(p_nl, probe.pred_test)
        )
        r_row.update(reg=float(probe.reg), reg_source=REG_CV, **r_fid)
        ridge_rows.append(r_row)
        g.say(
            f"{tg.name}: V+T_{inp.removeprefix('t_')} delta {r_row['delta']:+.3f} "
            f"[{r_row['ci_low']:+.3f}, {r_row['ci_high']:+.3f}], cos "
            f"{r_fid['cos_matched']:.3f} vs {r_fid['cos_offdiag']:.3f}"
        )
    return ridge_rows, ridge_pred, ridge_gaps


def _repeated(
    g: _Generator,
    tg: TargetProbes,
    baselines: Mapping[str, Baselines],
    labels: Mapping[str, object] | None,
) -> _Repeated:
    """The rows of one target that do not depend on the cell, each bootstrapped once: V +
    T_real and nonlinear V (against the target's `fit_baselines`) and the ridge arms."""
    if tg.name not in baselines:
        raise ValueError(f"evaluate_generator: no baselines for target {tg.name!r}")
    bl = baselines[tg.name]
    p_v, p_real, p_nl = (np.asarray(bl.pred[k]) for k in BASELINE_INPUTS)
    if not len(p_v) == len(p_real) == len(p_nl) == tg.rows.n_test:
        raise ValueError(
            f"evaluate_generator: {tg.name} baselines are not on its {tg.rows.n_test} test rows"
        )
    base = _target_base(g, tg, bl.gamma, labels)
    real_row = summary_row({}, "t_real", tg.boot(p_v, p_real), tg.boot(p_nl, p_real))
    nl_row = summary_row({}, "v_nonlinear", tg.boot(p_v, p_nl), None)
    real_row.update(reg=bl.reg["t_real"], reg_source=REG_CV)
    nl_row.update(reg=bl.reg["v_nonlinear"], reg_source=REG_CV)
    ridge_rows, ridge_pred, ridge_gaps = _ridge_arms(g, tg, p_v, p_nl)
    g.say(
        f"{tg.name}: V {real_row['v_score']:.3f}, V+T_real delta {real_row['delta']:+.3f} "
        f"[{real_row['ci_low']:+.3f}, {real_row['ci_high']:+.3f}], nonlinear V delta "
        f"{nl_row['delta']:+.3f}"
    )
    return _Repeated(base, p_v, p_nl, real_row, nl_row, ridge_rows, ridge_pred, ridge_gaps)


def _cell_fidelity(
    g: _Generator, tg: TargetProbes, cell: tuple[str, str, str], g_te: np.ndarray
) -> tuple[dict, list[dict]]:
    """The fidelity of one cell's test vectors, and its permutation rows where it is computed
    here (none where a target on the same test rows computed it before)."""
    key = (cell, tuple(tg.rows.test_ids))
    perm_rows: list[dict] = []
    if key not in g.fid_cache:
        fid, null = fidelity(g_te, tg.t_te, tg.t_tr, n_permutations=g.permutations, seed=g.seed)
        g.fid_cache[key] = fid
        perm_rows = permutation_rows(g.corpus, g.seed, tg.name, cell, null, fid["cos_matched"])
    return g.fid_cache[key], perm_rows


def _cell_rows(
    g: _Generator,
    tg: TargetProbes,
    rep: _Repeated,
    cell: tuple[str, str, str],
    gen: Mapping[str, np.ndarray],
) -> tuple[list[dict], list[dict]]:
    """One cell's summary rows (V + T_real, V + T_gen, its shuffled control, nonlinear V and
    the ridge arms) and its permutation rows."""
    rows = tg.rows
    sampler, guidance, steps = cell
    cell_base = {**rep.base, "sampler": sampler, "guidance": float(guidance), "steps": int(steps)}
    g_tr, g_te = feature_block(gen, rows.train_ids), feature_block(gen, rows.test_ids)
    shuf = {i: gen[g.shuffled_of[i]] for i in g.vision}
    s_tr, s_te = feature_block(shuf, rows.train_ids), feature_block(shuf, rows.test_ids)
    p_gen, reg_gen, src_gen = tg.fit_cell(
        "t_gen", np.hstack([tg.v_tr, g_tr]), np.hstack([tg.v_te, g_te])
    )
    p_shuf, reg_shuf, src_shuf = tg.fit_cell(
        "t_gen_shuffled", np.hstack([tg.v_tr, s_tr]), np.hstack([tg.v_te, s_te])
    )
    fid, perm_rows = _cell_fidelity(g, tg, cell, g_te)
    gen_row = summary_row(
        cell_base,
        "t_gen",
        tg.boot(rep.p_v, p_gen, generated=True),
        tg.boot(rep.p_nl, p_gen),
        tg.boot(rep.ridge_pred["t_ridge"], p_gen, generated=True),
    )
    shuf_row = summary_row(
        cell_base,
        "t_gen_shuffled",
        tg.boot(rep.p_v, p_shuf, generated=True),
        tg.boot(rep.p_nl, p_shuf),
    )
    gen_row.update(reg=reg_gen, reg_source=src_gen)
    gen_row.update(
        pairing_gap_columns(centred_gaps(g_te, tg.t_te, tg.t_tr), rep.ridge_gaps, tg.resamples)
    )
    shuf_row.update(reg=reg_shuf, reg_source=src_shuf)
    rows_cell = [{**cell_base, **rep.real_row}, gen_row, shuf_row, {**cell_base, **rep.nl_row}]
    for r in rows_cell:
        r.update(fid)
    rows_cell += [{**cell_base, **r} for r in rep.ridge_rows]  # with their own fidelity
    for r in rows_cell:
        r["ridge_alpha"] = g.ridge_alpha
        r["row_id"] = summary_row_id(g.corpus, tg.name, g.seed, cell, r["input"])
    g.say(
        f"{tg.name} {sampler} w={guidance} steps={steps}: V+T_gen delta "
        f"{gen_row['delta']:+.3f} [{gen_row['ci_low']:+.3f}, {gen_row['ci_high']:+.3f}]"
        f" (C/lambda {reg_gen:g}, {src_gen}), vs nonlinear V "
        f"{gen_row['delta_vs_nonlinear']:+.3f}, vs ridge V->T "
        f"{gen_row['delta_vs_ridge']:+.3f}; shuffled {shuf_row['delta']:+.3f}; "
        f"cos {fid['cos_matched']:.3f} vs {fid['cos_offdiag']:.3f} "
        f"(p {fid['pairing_p']:.3f}), FD {fid['frechet']:.2f}"
    )
    return rows_cell, perm_rows


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
    (`evaluate_probes.family_interval`), from the same resamples as its CI. The rows' columns:
    `evaluate_rows.summary_row`; the draws': `evaluate_rows.permutation_frame`.
    """
    say = progress or (lambda _m: None)
    ridge = ridge_generate(vision, t_real, generator_train_ids, seed=seed, alphas=RIDGE_ALPHAS)
    say(f"ridge V->T generator: alpha {ridge.alpha:g} by leave-one-out on {ridge.n_train} rows")
    all_ids = np.array(sorted(vision), dtype=object)
    perm = shuffled_rows(len(all_ids), seed)
    g = _Generator(
        corpus=corpus,
        seed=seed,
        permutations=permutations,
        vision=vision,
        shuffled_of=dict(zip(all_ids, all_ids[perm], strict=True)),
        ridge_alpha=ridge.alpha,
        ridge_sources=dict(zip(RIDGE_INPUTS, (ridge.mean, ridge.residual), strict=True)),
        say=say,
    )
    cells = _cell_order(list(t_gen), reference)
    out_rows: list[dict] = []
    perm_rows: list[dict] = []
    for spec in targets:
        tg = target_probes(spec, vision, t_real, family)
        rep = _repeated(g, tg, baselines, labels)
        for cell in cells:
            rows_cell, perms = _cell_rows(g, tg, rep, cell, t_gen[cell])
            perm_rows += perms
            out_rows += rows_cell
    return pd.DataFrame(out_rows), permutation_frame(perm_rows)
