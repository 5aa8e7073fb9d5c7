"""Logistic probes on frozen features (density, hardness): scikit-learn's lbfgs, CV over C.

This module owns:

- `fit_logistic` / `LogisticProbe`: scikit-learn ``LogisticRegression`` (lbfgs; multinomial
  for more than two classes; each fit solved by `lbfgs.fit_lbfgs_logistic`, scikit-learn's
  objective and scipy call without its per-iteration overhead) on standardised features, C
  chosen by stratified K-fold CV on the training rows (the K folds of each C solved together
  by `batched.fit_logistic_batch` where `cv_batches` allows it, else one fold at a time: on
  two classes the fold's whole C grid as one Newton path, `newton.newton_logistic_path`; on
  more, one lbfgs fit per C. The same objective and stopping rule throughout, so the CV
  scores agree with scikit-learn's loop up to held-out rows whose decision is within the
  solvers' tolerance of 0). Convergence is never silently assumed:
  lbfgs runs up to ``max_iter`` (by default the cap itself, one run: lbfgs's iterates do not
  depend on its iteration budget, so a first run at 200 that is doubled until it converges
  returns the same coefficients bit for bit after about twice the work); an unconverged run (where scikit-learn would
  warn) doubles a smaller ``max_iter`` and refits, up to the cap; iterations and convergence
  are recorded, and a probe that still fails to converge re-emits the warning.
- `FixedLogistic`: the probe at its chosen C; `FixedLogistic.refit_many` solves a control's
  B refits (`refits.Refits`) together with `batched.fit_logistic_batch` where that solver
  is measured faster, else one `fit_logistic_once` fit at a time.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

from tacgen_lib.probes.batched import fit_logistic_batch
from tacgen_lib.probes.blas_threads import single_blas_thread
from tacgen_lib.probes.bootstrap import resample_counts
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.input_checks import check_features, check_target
from tacgen_lib.probes.lbfgs import fit_lbfgs_logistic
from tacgen_lib.probes.metrics import accuracy
from tacgen_lib.probes.newton import newton_logistic_path
from tacgen_lib.probes.objective import standardise_block
from tacgen_lib.probes.refits import Refits, Refitted

__all__ = [
    "FixedLogistic",
    "LogisticFit",
    "LogisticProbe",
    "cv_batches",
    "fit_logistic",
    "fit_logistic_once",
]


@dataclass(frozen=True)
class LogisticFit:
    """One converged (or honestly unconverged) standardised logistic regression."""

    model: Pipeline
    n_iter: int
    max_iter: int
    converged: bool


def fit_logistic_once(
    X: np.ndarray, y: np.ndarray, C: float, max_iter: int, max_iter_cap: int, tol: float
) -> LogisticFit:
    """Standardise (``StandardScaler`` on these rows) + scikit-learn's lbfgs
    ``LogisticRegression`` (solved by `lbfgs.fit_lbfgs_logistic`: scikit-learn's objective and
    iterates without its per-iteration overhead); double max_iter (up to the cap) where lbfgs
    stops unconverged (where scikit-learn would warn). A fit that still fails at the cap emits
    a ConvergenceWarning and is recorded as converged=False.
    """
    it = max_iter
    scaler = StandardScaler().fit(X)
    Xs = scaler.transform(X)
    while True:
        with single_blas_thread():
            fit = fit_lbfgs_logistic(Xs, y, C, max_iter=it, tol=tol)
        model = Pipeline([("standardise", scaler), ("logistic", fit.model)])
        if fit.converged:
            return LogisticFit(model, fit.n_iter, it, True)
        if it >= max_iter_cap:
            warnings.warn(
                f"fit_logistic: lbfgs did not converge within max_iter={it} (C={C}); "
                "the probe is recorded as converged=False -- check feature scaling or C",
                ConvergenceWarning,
                stacklevel=3,
            )
            return LogisticFit(model, fit.n_iter, it, False)
        it = min(2 * it, max_iter_cap)


@dataclass(frozen=True)
class LogisticProbe:
    """A logistic probe: CV-selected C, refit diagnostics, and the fitted pipeline."""

    C: float
    C_grid: np.ndarray
    cv_scores: np.ndarray  # (len(C_grid),) mean held-out accuracy
    fit: LogisticFit
    cv_converged: bool  # every fold fit converged
    cv_max_n_iter: int  # most lbfgs iterations of a CV fit, or Newton steps of a fold's path

    @property
    def n_iter(self) -> int:
        return self.fit.n_iter

    @property
    def converged(self) -> bool:
        return self.fit.converged

    def predict(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        return self.fit.model.predict(check_features(X, name="X_test", sample_ids=sample_ids))

    def predict_proba(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        X = check_features(X, name="X_test", sample_ids=sample_ids)
        return self.fit.model.predict_proba(X)


def fit_logistic(
    X: np.ndarray,
    y: np.ndarray,
    C_grid: Sequence[float],
    seed: int,
    *,
    n_folds: int,
    repeats: int,
    max_iter: int = 12800,
    max_iter_cap: int = 12800,
    tol: float = 1e-6,
    sample_ids: Sequence | np.ndarray | None = None,
    batched: bool = True,
) -> LogisticProbe:
    """Logistic probe (density, hardness): C by stratified K-fold CV on the training rows
    (`repeats` draws of the folds: the CV score is the mean over all of them).

    Features are standardised inside every fit (scaler fitted on that fit's training rows
    only), which keeps lbfgs well conditioned; with the L2 penalty the objective is strictly
    convex with a finite minimiser even for linearly separable classes, so lbfgs converges.
    Ties in CV accuracy go to the first C of the grid in the order given. ``tol`` is tighter
    than scikit-learn's 1e-4 default so the fitted probabilities agree with a float64
    reference optimum to ~1e-5. The CV's folds are solved together by the batched solver
    where every fold keeps at least as many rows as features (`cv_batches`) and ``batched``
    is True, else one `fit_logistic_once` fit at a time; the final fit at the chosen C is
    always `fit_logistic_once`'s (scikit-learn's problem and iterates). Pass
    ``batched=False`` for features on which the batched solve is known not to finish within
    its budget (`CV_BATCH_BUDGET`), where it only adds its iterations.
    """
    X = check_features(X, sample_ids=sample_ids)
    y = check_target(y, X.shape[0], sample_ids=sample_ids, numeric=False)
    C = np.asarray(C_grid, dtype=np.float64)
    if C.ndim != 1 or C.size == 0 or not (np.isfinite(C).all() and (C > 0).all()):
        raise ValueError(f"fit_logistic: C_grid must be a non-empty list of C > 0, got {C_grid}")
    classes, counts = np.unique(y, return_counts=True)
    if classes.size < 2:
        raise ValueError("fit_logistic: training rows hold a single class; nothing to probe")
    k = int(min(n_folds, counts.min()))
    if k < 2:
        raise ValueError(
            f"fit_logistic: class {classes[np.argmin(counts)]!r} has {counts.min()} training "
            "row(s); stratified CV needs at least 2 per class"
        )
    folds = make_folds(X.shape[0], k, seed, labels=y, repeats=repeats)
    if batched and cv_batches(X.shape, folds):
        scores, all_conv, worst = _cv_scores_batched(
            X, y, folds, C, max_iter, max_iter_cap, tol, CV_BATCH_BUDGET
        )
    else:
        scores = np.zeros((len(folds), C.size))
        all_conv = True
        worst = 0
        for f, ho in enumerate(folds):
            if classes.size == 2:  # the fold's C path by Newton's method (`newton`)
                scores[f], conv, n_iter = _fold_path_scores(X, y, ho, C, tol)
                all_conv &= conv
                worst = max(worst, n_iter)
                continue
            for c, cval in enumerate(C):
                scores[f, c], conv, n_iter = _fold_score(
                    X, y, ho, float(cval), max_iter, max_iter_cap, tol
                )
                all_conv &= conv
                worst = max(worst, n_iter)
    cv = scores.mean(axis=0)
    best = float(C[int(np.argmax(cv))])
    final = fit_logistic_once(X, y, best, max_iter, max_iter_cap, tol)
    return LogisticProbe(best, C, cv, final, bool(all_conv), int(worst))


def cv_batches(shape: tuple[int, int], folds: Sequence[np.ndarray]) -> bool:
    """Whether `fit_logistic`'s CV solves its folds together (`_cv_scores_batched`).

    When every fold's training part has at least as many rows as there are features: the
    batched solver preconditions with the shared scatter, and a fold that drops rows from a
    design with fewer rows than columns has directions whose only curvature is the L2 term,
    which that scatter does not see (`FixedLogistic.batches`, the same rule for the controls).
    """
    n, p = shape
    return n - max(len(ho) for ho in folds) >= p


#: Iterations the batched CV solve may take before the folds it has not solved are refitted
#: one at a time. Its iterations cost several one-fold iterations each (numpy call overhead,
#: not FLOPs), so it pays only when preconditioning cuts the iterations several-fold: it does
#: on the ViT probes (V, V+T: tens to about a hundred iterations against the loop's hundreds,
#: same scores and C), not on V + an RBF Nystroem map (the generator's nonlinear baseline),
#: where it needs hundreds to thousands and an unbounded batched solve is many times slower
#: than the loop. benchmarks/bench_probes.py prints both solvers' times on a hardness-like
#: probe.
CV_BATCH_BUDGET = 200


def _cv_scores_batched(
    X: np.ndarray,
    y: np.ndarray,
    folds: Sequence[np.ndarray],
    C: np.ndarray,
    max_iter: int,
    max_iter_cap: int,
    tol: float,
    budget: int,
) -> tuple[np.ndarray, bool, int]:
    """(folds x C held-out accuracies, every fit converged, most iterations) of the CV, the
    K folds of each C solved together by `batched.fit_logistic_batch`.

    Fold f is problem f: its held-out rows get weight 0, and its block is standardised on its
    own training rows (`standardise_block` with those weights: StandardScaler on X[train]);
    the held-out rows are predicted under that scaler, ties as scikit-learn. The objective and
    the stopping rule (max |gradient| <= tol) are scikit-learn's lbfgs's, so the held-out
    labels are scikit-learn's wherever a row's decision is not within the solvers' tolerance of
    0; a row that is can fall the other way, and where two C are within such a row of each
    other in CV score the C chosen can differ from the loop's (the synthetic probe of
    benchmarks/bench_probes.py: C 1 against 10; on the default config's probes no selection
    changed). The probe's final fit at the chosen C stays `fit_logistic_once`'s. A fold the
    batched solve has not finished within `budget` iterations is refitted by it, as the loop
    would (`CV_BATCH_BUDGET`). Faster than the one-fit-at-a-time loop on the ViT probes
    (benchmarks/bench_probes.py prints the two on a hardness-like probe).
    """
    n = X.shape[0]
    weights = np.ones((len(folds), n))
    for f, ho in enumerate(folds):
        weights[f, ho] = 0.0
    block = standardise_block(np.asarray(X, dtype=np.float64), weights=weights)
    classes = np.unique(y)
    scores = np.zeros((len(folds), C.size))
    all_conv, worst = True, 0
    for c, cval in enumerate(C):
        batch = fit_logistic_batch(
            [block],
            y,
            float(cval),
            sample_weight=weights,
            classes=classes,
            tol=tol,
            max_iter=min(budget, max_iter_cap),
        )
        pred = batch.predict([block])  # (folds, n): every row under each fold's fit
        for f, ho in enumerate(folds):
            if batch.converged[f]:
                scores[f, c] = accuracy(y[ho], pred[f, ho])
                worst = max(worst, int(batch.n_iter[f]))
                continue
            scores[f, c], conv, n_iter = _fold_score(
                X, y, ho, float(cval), max_iter, max_iter_cap, tol
            )
            all_conv &= conv
            worst = max(worst, n_iter)
    return scores, all_conv, worst


def _fold_score(
    X: np.ndarray,
    y: np.ndarray,
    ho: np.ndarray,
    C: float,
    max_iter: int,
    max_iter_cap: int,
    tol: float,
) -> tuple[float, bool, int]:
    """(held-out accuracy, converged, iterations) of one `fit_logistic_once` fit on every row
    outside the fold `ho`: one fold and C of the CV's loop, and the batched CV's fallback."""
    tr = np.setdiff1d(np.arange(X.shape[0]), ho, assume_unique=True)
    fit = fit_logistic_once(X[tr], y[tr], C, max_iter, max_iter_cap, tol)
    return accuracy(y[ho], fit.model.predict(X[ho])), fit.converged, fit.n_iter


def _fold_path_scores(
    X: np.ndarray, y: np.ndarray, ho: np.ndarray, C: np.ndarray, tol: float
) -> tuple[np.ndarray, bool, int]:
    """(held-out accuracy per C, every fit converged, most Newton steps) of one fold of the
    CV's loop on two classes: the fold's training rows standardised as `fit_logistic_once`
    does (``StandardScaler`` on them), its C grid solved as one path from the strongest penalty
    to the weakest by `newton.newton_logistic_path` (the same objective and stopping rule as
    lbfgs's), the held-out rows labelled as scikit-learn's ``predict`` does (the second class
    where the decision is > 0)."""
    tr = np.setdiff1d(np.arange(X.shape[0]), ho, assume_unique=True)
    scaler = StandardScaler().fit(X[tr])
    classes = np.unique(y[tr])
    order = np.argsort(C, kind="stable")
    with single_blas_thread():  # as lbfgs's fits: the same bits for any thread count
        path = newton_logistic_path(scaler.transform(X[tr]), y[tr] == classes[1], C[order], tol=tol)
    held_out = scaler.transform(X[ho])
    scores = np.zeros(C.size)
    for c, fit in zip(order, path, strict=True):
        scores[c] = accuracy(y[ho], classes[(fit.decision(held_out) > 0).astype(int)])
    return scores, all(fit.converged for fit in path), max(fit.n_iter for fit in path)


@dataclass(frozen=True)
class FixedLogistic:
    """Logistic probe at a fixed C, for controls and resampling diagnostics."""

    C: float
    max_iter: int = 12800
    max_iter_cap: int = 12800
    tol: float = 1e-6

    def fit_predict(self, X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray):
        fit = fit_logistic_once(
            np.asarray(X_train, dtype=np.float64),
            np.asarray(y_train),
            self.C,
            self.max_iter,
            self.max_iter_cap,
            self.tol,
        )
        return fit.model.predict(np.asarray(X_test, dtype=np.float64))

    def batches(self, refits: Refits) -> bool:
        """Whether `refit_many` solves these refits with `batched.fit_logistic_batch`.

        Every problem set whose refits share one unweighted design (tactile and label
        permutations). Refits whose design differs per problem (bootstrap row weights,
        private random-feature blocks) only when ``n_train >= n_features``: the solver's
        preconditioner comes from the shared scatter, and with fewer rows than columns a
        problem that drops or reweights rows has directions whose only curvature is the L2
        term, which that scatter does not see. On the default density probe (3 classes,
        fewer rows than columns) the batched solve is several times slower than the loop for
        train resamples and random features (so both loop there) and several times faster
        for tactile and label permutations; on hardness (more rows than columns) it is an
        order of magnitude faster or more in every control (benchmarks/bench_probes.py
        prints the permutation controls of a hardness-like probe). Only concatenated blocks batch (other fusions are
        not linear in the blocks), and an empty batch has nothing to solve.
        """
        if refits.fusion != "concat" and len(refits.train) > 1 or refits.n_problems == 0:
            return False
        return refits.shared_design or refits.n_train >= refits.n_features

    def refit_many(self, refits: Refits, *, batched: bool | None = None) -> Refitted:
        """(B, m) test labels of B refits at this C and tol.

        Batched (by `batches`, or as asked: a control's V side follows its V+T side, so both
        sides of a Delta come from the same solver): each training block is standardised per
        problem (`standardise_block`, with the bootstrap counts as row weights) and all
        problems are solved together; a bootstrap problem that misses a class is refitted
        alone (scikit-learn then fits the classes present, or refuses a single class). Each
        problem that reaches the iteration cap unconverged emits one ConvergenceWarning, as
        a refit of `fit_predict` would.
        """
        if not (self.batches(refits) if batched is None else batched):
            return Refitted(refits.loop(self.fit_predict), {"refits": refits.n_problems})
        y = np.asarray(refits.y)
        todo, alone = np.arange(refits.n_problems), np.zeros(0, dtype=np.int64)
        weights = None
        if refits.rows is not None:
            counts = resample_counts(refits.rows, refits.n_train)
            held = np.stack([counts[:, y == c].sum(axis=1) > 0 for c in np.unique(y)], axis=1)
            todo, alone = np.flatnonzero(held.all(axis=1)), np.flatnonzero(~held.all(axis=1))
            weights = counts[todo]
        pred = np.empty((refits.n_problems, refits.n_test), dtype=object)
        if todo.size:
            train = [standardise_block(b.data, weights=weights, perm=b.perm) for b in refits.train]
            test = [
                fit.transform(b.data, b.perm) for fit, b in zip(train, refits.test, strict=True)
            ]
            batch = fit_logistic_batch(
                train, y, self.C, sample_weight=weights, tol=self.tol, max_iter=self.max_iter_cap
            )
            for b in np.flatnonzero(~batch.converged):
                warnings.warn(
                    f"fit_logistic_batch: problem {int(b)} did not converge within "
                    f"{self.max_iter_cap} iterations (C={self.C})",
                    ConvergenceWarning,
                    stacklevel=3,
                )
            labels = batch.predict(test)
            if not alone.size:
                return Refitted(labels, {"batched_logistic": int(todo.size)})
            pred[todo] = labels
        pred[alone] = refits.loop(self.fit_predict, alone)
        return Refitted(pred, {"batched_logistic": int(todo.size), "refits": int(alone.size)})
