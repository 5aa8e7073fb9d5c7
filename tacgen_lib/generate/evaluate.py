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
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import linalg
from scipy.spatial.distance import pdist
from sklearn.kernel_approximation import Nystroem

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap, resample_indices
from tacgen_lib.probes.fit import FittedProbe, fit_probe
from tacgen_lib.probes.logistic import FixedLogistic
from tacgen_lib.probes.rows import FamilyRows, family_rows, strata_for
from tacgen_lib.probes.settings import ProbeSettings

__all__ = [
    "INPUTS",
    "FIDELITY_COLUMNS",
    "PERMUTATION_COLUMNS",
    "BASELINE_INPUTS",
    "Baselines",
    "TargetSpec",
    "baselines_frame",
    "baselines_from_frame",
    "cosine_pairing",
    "evaluate_generator",
    "fit_baselines",
    "target_specs",
    "fidelity",
    "frechet_distance",
    "nonlinear_baseline",
    "pairing_permutation",
    "shuffled_rows",
]

#: What is added to V in a summary row.
INPUTS = ("t_real", "t_gen", "t_gen_shuffled", "v_nonlinear")
FIDELITY_COLUMNS = ("cos_matched", "cos_offdiag", "pairing_p", "frechet", "frechet_real_ref")
#: Columns of the permutation-draw table (one row per cell, target and permutation).
PERMUTATION_COLUMNS = (
    "row_id",
    "corpus",
    "seed",
    "target",
    "sampler",
    "guidance",
    "steps",
    "permutation",
    "statistic",
    "observed",
)


def frechet_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Frechet distance between Gaussians fitted to the rows of `a` and `b` (float64).

    ||mu_a - mu_b||^2 + tr(S_a + S_b - 2 (S_a^1/2 S_b S_a^1/2)^1/2): the symmetric form, whose
    square roots are of PSD matrices (eigh, negative round-off eigenvalues set to 0), so it
    stays real and finite where sqrtm(S_a S_b) can turn complex.
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or len(a) < 2 or len(b) < 2:
        raise ValueError(
            f"frechet_distance: need (n >= 2, d) arrays of one d, got {a.shape}, {b.shape}"
        )
    mu = a.mean(0) - b.mean(0)
    s_a, s_b = np.cov(a, rowvar=False), np.cov(b, rowvar=False)

    def psd_sqrt(m: np.ndarray) -> np.ndarray:
        w, v = linalg.eigh((m + m.T) / 2.0)
        return (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T

    r = psd_sqrt(s_a)
    cross = psd_sqrt(r @ s_b @ r)
    return float(max(mu @ mu + np.trace(s_a) + np.trace(s_b) - 2.0 * np.trace(cross), 0.0))


def _unit(x: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(x, axis=1, keepdims=True)
    return x / np.where(n > 0, n, 1.0)


def cosine_pairing(gen: np.ndarray, real: np.ndarray) -> tuple[float, float]:
    """(mean cos(gen_i, real_i), mean over i != j of cos(gen_i, real_j)); rows already centred."""
    g, r = _unit(np.asarray(gen, np.float64)), _unit(np.asarray(real, np.float64))
    sims = g @ r.T
    n = sims.shape[0]
    matched = float(np.mean(np.diag(sims)))
    off = float((sims.sum() - np.trace(sims)) / (n * (n - 1))) if n > 1 else float("nan")
    return matched, off


def pairing_permutation(
    gen: np.ndarray, real: np.ndarray, n_permutations: int, seed: int
) -> tuple[float, np.ndarray, float]:
    """Matched mean cosine against `n_permutations` re-pairings of generated and real rows.

    Returns (observed, permuted statistics, one-sided p = (1 + #{perm >= observed}) / (1 + B)).
    """
    g, r = _unit(np.asarray(gen, np.float64)), _unit(np.asarray(real, np.float64))
    sims = g @ r.T
    n = sims.shape[0]
    observed = float(np.mean(np.diag(sims)))
    if n_permutations <= 0:
        return observed, np.zeros(0), float("nan")
    rng = np.random.default_rng(seed)
    perms = np.argsort(rng.random((n_permutations, n)), axis=1, kind="stable")
    null = sims[perms, np.arange(n)[None, :]].mean(axis=1)
    p = float((1 + np.sum(null >= observed)) / (1 + n_permutations))
    return observed, null, p


def fidelity(
    gen_test: np.ndarray,
    real_test: np.ndarray,
    real_train: np.ndarray,
    *,
    n_permutations: int,
    seed: int,
) -> tuple[dict[str, float], np.ndarray]:
    """The cell's fidelity columns (`FIDELITY_COLUMNS`) and its permutation distribution."""
    centre = np.asarray(real_train, np.float64).mean(axis=0)
    g, r = np.asarray(gen_test, np.float64) - centre, np.asarray(real_test, np.float64) - centre
    matched, off = cosine_pairing(g, r)
    _, null, p = pairing_permutation(g, r, n_permutations, seed)
    out = {
        "cos_matched": matched,
        "cos_offdiag": off,
        "pairing_p": p,
        "frechet": frechet_distance(gen_test, real_test),
        "frechet_real_ref": frechet_distance(real_train, real_test),
    }
    return out, null


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


def _standardise(train: np.ndarray, test: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mu, sd = train.mean(0), train.std(0)
    sd = np.where(sd > 0, sd, 1.0)
    return (train - mu) / sd, (test - mu) / sd


def nonlinear_baseline(
    v_train: np.ndarray,
    v_test: np.ndarray,
    rows: FamilyRows,
    settings: ProbeSettings,
    *,
    gammas: Sequence[float],
    n_components: int,
    seed: int,
) -> tuple[FittedProbe, float]:
    """The nonlinear V-only baseline: the family's probe on [V, phi(V)], tuned on train rows.

    phi: RBF Nystroem features of standardised V (fitted on the train rows), gamma =
    multiple / median squared train distance; the multiple with the best CV score wins.
    Returns the fitted probe and the chosen gamma.
    """
    z_tr, z_te = _standardise(np.asarray(v_train, np.float64), np.asarray(v_test, np.float64))
    sub = z_tr[: min(len(z_tr), 500)]
    # pairwise squared distances i < j (pdist: no (n, n, d) temporary)
    med = float(np.median(pdist(sub, "sqeuclidean"))) if len(sub) > 1 else 1.0
    med = med if med > 0 else 1.0
    best: tuple[float, FittedProbe, float] | None = None
    for mult in gammas:
        gamma = float(mult) / med
        k = min(n_components, len(z_tr))
        phi = Nystroem(kernel="rbf", gamma=gamma, n_components=k, random_state=seed).fit(z_tr)
        x_tr = np.hstack([v_train, phi.transform(z_tr)])
        x_te = np.hstack([v_test, phi.transform(z_te)])
        fit = fit_probe(
            x_tr, rows.y_train, x_te, settings, train_ids=rows.train_ids, test_ids=rows.test_ids
        )
        cv = float(np.nanmax(fit.cv_scores))
        if best is None or cv > best[0]:
            best = (cv, fit, gamma)
    assert best is not None
    return best[1], best[2]


@dataclass(frozen=True)
class TargetSpec:
    """One generator target: a probe family's rows and settings, and its name."""

    name: str
    rows: FamilyRows
    settings: ProbeSettings


def target_specs(
    manifest: pd.DataFrame,
    splits: pd.DataFrame,
    *,
    corpus: str,
    targets: Mapping[str, str],
    corpus_config: Mapping,
    probes_config: Mapping,
    probe_seed: int,
    rule: str,
) -> list[TargetSpec]:
    """The `TargetSpec` of each generator target of `corpus` (target -> ridge | logistic).

    The probes' rows (`family_rows`, the probes stage's strata) train on train + val rows, as
    in the probes stage: `assert_trainable` refuses any test row in them, naming `rule`.
    """
    out = []
    for target, kind in targets.items():
        rows = family_rows(
            manifest,
            splits,
            corpus=corpus,
            target=target,
            kind=kind,
            strata=strata_for(corpus_config),
        )
        assert_trainable(rows.train_ids, splits, rule=rule, allowed=("train", "val"))
        out.append(
            TargetSpec(target, rows, ProbeSettings.from_config(probes_config, kind, probe_seed))
        )
    return out


#: The probes of the baselines edge, by what they fit: V alone, V + T_real, V + phi(V).
BASELINE_INPUTS = ("v", "t_real", "v_nonlinear")
#: Columns of the baselines edge (one row per target x baseline input x test row).
BASELINE_COLUMNS = (
    "row_id",
    "corpus",
    "target",
    "kind",
    "input",
    "sample_id",
    "prediction",
    "label",
    "reg",
    "nonlinear_gamma",
)


def _block(source: Mapping[str, np.ndarray], ids: np.ndarray) -> np.ndarray:
    """Rows `ids` of a sample_id -> vector mapping, stacked as float64."""
    return np.stack([source[i] for i in ids]).astype(np.float64)


@dataclass(frozen=True)
class Baselines:
    """The probes of one target that no generator changes, fitted once per corpus.

    ``pred``: input (`BASELINE_INPUTS`) -> test predictions in ``rows.test_ids`` order (floats
    for ridge, labels for logistic); ``reg``: input -> the lambda or C its CV chose;
    ``gamma``: the nonlinear baseline's RBF gamma.
    """

    target: str
    pred: Mapping[str, np.ndarray]
    reg: Mapping[str, float]
    gamma: float


def fit_baselines(
    spec: TargetSpec,
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    *,
    gammas: Sequence[float],
) -> Baselines:
    """V alone, V + T_real and the nonlinear V baseline of one target (module docstring).

    Nothing here depends on a generator, so one fit per corpus serves every generator seed;
    the nonlinear baseline's Nystroem draw uses the probe seed.
    """
    rows, ps = spec.rows, spec.settings
    v_tr, v_te = _block(vision, rows.train_ids), _block(vision, rows.test_ids)
    t_tr, t_te = _block(t_real, rows.train_ids), _block(t_real, rows.test_ids)

    def fit(x_tr: np.ndarray, x_te: np.ndarray) -> FittedProbe:
        return fit_probe(
            x_tr, rows.y_train, x_te, ps, train_ids=rows.train_ids, test_ids=rows.test_ids
        )

    v_fit, real_fit = fit(v_tr, v_te), fit(np.hstack([v_tr, t_tr]), np.hstack([v_te, t_te]))
    nl, gamma = nonlinear_baseline(
        v_tr, v_te, rows, ps, gammas=gammas, n_components=t_tr.shape[1], seed=ps.seed
    )
    fits = {"v": v_fit, "t_real": real_fit, "v_nonlinear": nl}
    return Baselines(
        spec.name,
        {k: f.pred_test for k, f in fits.items()},
        {k: float(f.reg) for k, f in fits.items()},
        float(gamma),
    )


def baselines_frame(
    corpus: str, specs: Sequence[TargetSpec], fits: Sequence[Baselines]
) -> pd.DataFrame:
    """The baselines edge: one row per target x input x test row (`BASELINE_COLUMNS`).

    Ridge predictions go to ``prediction`` (float64, bit-exact through Parquet), logistic
    labels to ``label`` (the targets' labels are strings); the other column is NaN / "".
    """
    out = []
    for spec, b in zip(specs, fits, strict=True):
        if spec.name != b.target:
            raise ValueError(f"baselines_frame: target {spec.name!r} got the fit of {b.target!r}")
        logistic = spec.settings.kind == "logistic"
        for inp in BASELINE_INPUTS:
            pred = np.asarray(b.pred[inp])
            for sid, value in zip(spec.rows.test_ids, pred, strict=True):
                out.append(
                    {
                        "row_id": f"{spec.name}|{inp}|{sid}",
                        "corpus": corpus,
                        "target": spec.name,
                        "kind": spec.settings.kind,
                        "input": inp,
                        "sample_id": str(sid),
                        "prediction": np.nan if logistic else float(value),
                        "label": str(value) if logistic else "",
                        "reg": b.reg[inp],
                        "nonlinear_gamma": b.gamma,
                    }
                )
    return pd.DataFrame(out, columns=list(BASELINE_COLUMNS))


def baselines_from_frame(
    frame: pd.DataFrame, specs: Sequence[TargetSpec], *, source: str = "baselines edge"
) -> dict[str, Baselines]:
    """Target -> `Baselines` read back from `baselines_frame`'s rows, checked against `specs`.

    Every target and input must hold exactly the spec's test rows (same sample_ids), and
    every logistic label must be a class of the training rows; anything else is an error
    naming `source`, the target and the offending sample_id (the edge was built from other
    splits or another probe config).
    """
    out: dict[str, Baselines] = {}
    for spec in specs:
        rows, logistic = spec.rows, spec.settings.kind == "logistic"
        sub = frame[frame["target"] == spec.name]
        if sub.empty:
            raise ValueError(f"{source}: no rows for target {spec.name!r}")
        pred, reg = {}, {}
        want = [str(i) for i in rows.test_ids]
        classes = {str(c): c for c in np.unique(rows.y_train)}
        for inp in BASELINE_INPUTS:
            part = sub[sub["input"] == inp].set_index("sample_id")
            got = set(part.index)
            missing = [i for i in want if i not in got]
            extra = sorted(got - set(want))
            if missing or extra:
                bad = (missing or extra)[0]
                raise ValueError(
                    f"{source}: target {spec.name!r} input {inp!r} does not hold this "
                    f"evaluation's test rows ({len(missing)} missing, {len(extra)} extra; "
                    f"sample_id {bad!r}): rebuild it from the same splits and probe config"
                )
            part = part.loc[want]
            if logistic:
                unknown = part.index[~part["label"].isin(list(classes))]
                if len(unknown):
                    raise ValueError(
                        f"{source}: target {spec.name!r} input {inp!r}, sample_id "
                        f"{unknown[0]!r}: label {part.loc[unknown[0], 'label']!r} is not a "
                        f"training class ({sorted(classes)})"
                    )
                pred[inp] = np.array([classes[x] for x in part["label"]], dtype=object)
            else:
                pred[inp] = part["prediction"].to_numpy(dtype=np.float64)
            reg[inp] = float(part["reg"].iloc[0])
        out[spec.name] = Baselines(spec.name, pred, reg, float(sub["nonlinear_gamma"].iloc[0]))
    return out


def _row(base: dict, inp: str, boot: dict, vs_nl: dict | None) -> dict:
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
    }


#: ``reg_source`` of a probe whose regulariser was chosen by its own CV / taken from the
#: reference cell's CV of the same input kind (logistic t_gen and t_gen_shuffled only).
REG_CV, REG_REFERENCE = "cv", "reference cell"


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
    reference: tuple[str, str, str] | None = None,
    labels: Mapping[str, object] | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Summary rows (one per target x cell x input) and permutation draws of one generator.

    vision, t_real: sample_id -> vector, for every row of the corpus (dicts keep this
    function free of edge I/O); t_gen: (sampler, guidance, steps) -> sample_id -> vector;
    baselines: target -> its `fit_baselines` (V, V + T_real, nonlinear V: shared by seeds).
    `reference`: the cell whose CV chooses the logistic C of every cell (module docstring;
    default: the first cell).
    """
    say = progress or (lambda _m: None)

    all_ids = np.array(sorted(vision), dtype=object)
    perm = shuffled_rows(len(all_ids), seed)
    shuffled_of = dict(zip(all_ids, all_ids[perm], strict=True))
    cells = _cell_order(list(t_gen), reference)
    out_rows: list[dict] = []
    perm_rows: list[dict] = []
    fid_cache: dict[tuple, dict] = {}
    for spec in targets:
        rows, ps = spec.rows, spec.settings
        v_tr, v_te = _block(vision, rows.train_ids), _block(vision, rows.test_ids)
        t_tr, t_te = _block(t_real, rows.train_ids), _block(t_real, rows.test_ids)
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
        ) -> dict:
            return fixed_test_bootstrap(
                rows.y_test,
                pred_a,
                pred_b,
                ps.metric,
                n_resamples=ps.bootstrap,
                seed=ps.seed,
                indices=resamples,
                sample_ids=rows.test_ids,
            )

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
            "nonlinear_gamma": gamma,
            **(labels or {}),
        }
        # the rows every cell repeats (they do not depend on the cell): bootstrapped once
        real_row = _row({}, "t_real", boot(p_v, p_real), boot(p_nl, p_real))
        nl_row = _row({}, "v_nonlinear", boot(p_v, p_nl), None)
        real_row.update(reg=bl.reg["t_real"], reg_source=REG_CV)
        nl_row.update(reg=bl.reg["v_nonlinear"], reg_source=REG_CV)
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
            g_tr, g_te = _block(gen, rows.train_ids), _block(gen, rows.test_ids)
            shuf = {i: gen[shuffled_of[i]] for i in vision}
            s_tr, s_te = _block(shuf, rows.train_ids), _block(shuf, rows.test_ids)
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
            gen_row = _row(cell_base, "t_gen", boot(p_v, p_gen), boot(p_nl, p_gen))
            shuf_row = _row(cell_base, "t_gen_shuffled", boot(p_v, p_shuf), boot(p_nl, p_shuf))
            gen_row.update(reg=reg_gen, reg_source=src_gen)
            shuf_row.update(reg=reg_shuf, reg_source=src_shuf)
            rows_cell = [{**cell_base, **real_row}, gen_row, shuf_row, {**cell_base, **nl_row}]
            for r in rows_cell:
                r.update(fid)
                r["row_id"] = (
                    f"{corpus}|{spec.name}|seed~{seed}|{sampler}|w={guidance}|"
                    f"steps={steps}|{r['input']}"
                )
            out_rows += rows_cell
            say(
                f"{spec.name} {sampler} w={guidance} steps={steps}: V+T_gen delta "
                f"{gen_row['delta']:+.3f} [{gen_row['ci_low']:+.3f}, {gen_row['ci_high']:+.3f}]"
                f" (C/lambda {reg_gen:g}, {src_gen}), vs nonlinear V "
                f"{gen_row['delta_vs_nonlinear']:+.3f}; shuffled {shuf_row['delta']:+.3f}; "
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
