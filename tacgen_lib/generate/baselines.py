"""The probes no generator changes, fitted once per corpus: V alone, V + real T and the nonlinear
V-only baseline (V + RBF Nyström features of V, gamma and regulariser by CV on train rows), with
their test predictions as an edge every generator's evaluation reads (and checks).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.probes.fit import FittedProbe, fit_probe
from tacgen_lib.probes.rows import FamilyRows, family_rows, strata_for
from tacgen_lib.probes.settings import ProbeSettings


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
    cv_repeats: int,
    grids: Mapping[str, Sequence[float]] | None = None,
) -> list[TargetSpec]:
    """The `TargetSpec` of each generator target of `corpus` (target -> ridge | logistic),
    each probe's regulariser chosen by `cv_repeats` draws of the CV folds, among the ``C`` and
    ``lambdas`` of `grids` (config ``generate.C`` / ``generate.lambdas``: grids that reach the
    majority class and the train mean) where given, else the probes stage's.

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
        settings = replace(
            ProbeSettings.from_config(probes_config, kind, probe_seed), cv_repeats=cv_repeats
        )
        if grids is not None:
            settings = replace(
                settings,
                C=tuple(float(c) for c in grids["C"]),
                lambdas=tuple(float(v) for v in grids["lambdas"]),
            )
        out.append(TargetSpec(target, rows, settings))
    return out


def standardise(train: np.ndarray, test: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Train and test rows standardised by the train rows' mean and std (a constant column
    keeps std 1)."""
    mu, sd = train.mean(0), train.std(0)
    sd = np.where(sd > 0, sd, 1.0)
    return (train - mu) / sd, (test - mu) / sd


def median_sq_distance(z: np.ndarray) -> float:
    """The RBF median heuristic's scale: the median squared distance between the first 500
    rows of `z` (1 where it is 0 or undefined); gamma = multiple / this."""
    from scipy.spatial.distance import pdist  # SciPy: only where a nonlinear probe is fitted

    sub = z[: min(len(z), 500)]
    # pairwise squared distances i < j (pdist: no (n, n, d) temporary)
    med = float(np.median(pdist(sub, "sqeuclidean"))) if len(sub) > 1 else 1.0
    return med if med > 0 else 1.0


def nystroem_ridge(gamma: float, lam: float, *, rank: int, seed: int):
    """RBF kernel ridge with a low-rank kernel: ridge without intercept (penalty `lam`) on
    `rank` RBF Nystroem features (landmark rows drawn with `seed`), a scikit-learn pipeline.
    Ridge on the Nystroem map is kernel ridge with the kernel that map spans, so `lam` means
    what KernelRidge's alpha means: the regime's kernel ridge rung and the V ceiling's kernel
    ridge share it above their exact sizes."""
    from sklearn.kernel_approximation import Nystroem  # scikit-learn: only where fitted
    from sklearn.linear_model import Ridge
    from sklearn.pipeline import make_pipeline

    features = Nystroem(
        kernel="rbf", gamma=float(gamma), n_components=int(rank), random_state=int(seed)
    )
    return make_pipeline(features, Ridge(alpha=float(lam), fit_intercept=False))


@dataclass(frozen=True)
class NonlinearFit:
    """The nonlinear V-only baseline's fit: the probe, its RBF gamma and the multiple of the
    median heuristic that gamma is (the multiple CV chose)."""

    probe: FittedProbe
    gamma: float
    multiple: float


def nonlinear_baseline(
    v_train: np.ndarray,
    v_test: np.ndarray,
    y_train: np.ndarray,
    settings: ProbeSettings,
    *,
    gammas: Sequence[float],
    n_components: int,
    seed: int,
    train_ids: Sequence | np.ndarray | None = None,
    test_ids: Sequence | np.ndarray | None = None,
) -> NonlinearFit:
    """The nonlinear V-only baseline: the family's probe on [V, phi(V)], tuned on train rows.

    phi: RBF Nystroem features of standardised V (fitted on the train rows), gamma =
    multiple / median squared train distance; the multiple (among `gammas`) with the best CV
    score wins, the first on ties. train_ids / test_ids name rows in the probe's errors.
    """
    # imported here: the regime summary's readers take this module's columns without them
    from sklearn.kernel_approximation import Nystroem

    z_tr, z_te = standardise(np.asarray(v_train, np.float64), np.asarray(v_test, np.float64))
    med = median_sq_distance(z_tr)
    best: tuple[float, NonlinearFit] | None = None
    for mult in gammas:
        gamma = float(mult) / med
        k = min(n_components, len(z_tr))
        phi = Nystroem(kernel="rbf", gamma=gamma, n_components=k, random_state=seed).fit(z_tr)
        x_tr = np.hstack([v_train, phi.transform(z_tr)])
        x_te = np.hstack([v_test, phi.transform(z_te)])
        # the logistic CV one fold at a time: on V + an RBF Nystroem map the batched solve
        # needs far more iterations than its budget (probes.logistic CV_BATCH_BUDGET), so it
        # mostly falls back after spending them (the same C, gamma and CV scores, sooner)
        fit = fit_probe(
            x_tr,
            y_train,
            x_te,
            settings,
            train_ids=train_ids,
            test_ids=test_ids,
            batched_cv=False,
        )
        cv = float(np.nanmax(fit.cv_scores))
        if best is None or cv > best[0]:
            best = (cv, NonlinearFit(fit, gamma, float(mult)))
    assert best is not None
    return best[1]


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
    v_tr, v_te = feature_block(vision, rows.train_ids), feature_block(vision, rows.test_ids)
    t_tr, t_te = feature_block(t_real, rows.train_ids), feature_block(t_real, rows.test_ids)

    def fit(x_tr: np.ndarray, x_te: np.ndarray) -> FittedProbe:
        return fit_probe(
            x_tr, rows.y_train, x_te, ps, train_ids=rows.train_ids, test_ids=rows.test_ids
        )

    v_fit, real_fit = fit(v_tr, v_te), fit(np.hstack([v_tr, t_tr]), np.hstack([v_te, t_te]))
    nl = nonlinear_baseline(
        v_tr,
        v_te,
        rows.y_train,
        ps,
        gammas=gammas,
        n_components=t_tr.shape[1],
        seed=ps.seed,
        train_ids=rows.train_ids,
        test_ids=rows.test_ids,
    )
    fits = {"v": v_fit, "t_real": real_fit, "v_nonlinear": nl.probe}
    return Baselines(
        spec.name,
        {k: f.pred_test for k, f in fits.items()},
        {k: float(f.reg) for k, f in fits.items()},
        float(nl.gamma),
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
