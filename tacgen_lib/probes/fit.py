"""Fitting one probe the protocol's way: the family's regulariser chosen by CV on the training
rows only (ridge λ, logistic C, or a protocol variant's probe), and the fixed probe the
controls refit."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tacgen_lib.probes.refits import FixedProbe
from tacgen_lib.probes.ridge import FixedRidge, fit_ridge_probe
from tacgen_lib.probes.settings import ProbeSettings

# The probes built on scikit-learn (logistic, MLP, standardised ridge) are imported where they
# are fitted: a job that fits only ridge probes, or only reads the comparison tables, does not
# import scikit-learn.

#: lbfgs tolerance of the logistic refits inside controls: scikit-learn's default. The main
#: probes use `probes.fit_logistic`'s tighter 1e-6. Controls are distributions over hundreds of
#: refits; at 1e-4 the hardness tactile-permutation Δ_ctrl moved by a few thousandths against
#: 1e-6, while 1e-6 made the batched train-resample refits of the 3-class density probe run
#: for minutes.
CONTROL_TOL = 1e-4


# --------------------------------------------------------------------------- probes


@dataclass(frozen=True)
class FittedProbe:
    """A probe fitted on the training rows: test predictions, chosen regulariser, diagnostics."""

    pred_test: np.ndarray
    reg: float  # lambda or C chosen by CV
    grid: np.ndarray
    cv_scores: np.ndarray  # mean held-out score per grid value
    converged: bool
    # most L-BFGS iterations of any of its fits (the CV's folds, batched where
    # `logistic.cv_batches`, and the final scikit-learn fit); None for ridge (closed form)
    n_iter: int | None
    pred_grid: np.ndarray | None = None  # (L, m) test predictions at every lambda (ridge)
    fixed_probe: FixedProbe | None = None  # set by protocols other than raw
    notes: str = ""  # what the protocol chose beyond `reg` (e.g. the MLP's width)

    def fixed(self, kind: str) -> FixedProbe:
        """The probe at its chosen regulariser, for controls and resampling diagnostics."""
        if self.fixed_probe is not None:
            return self.fixed_probe
        if kind == "ridge":
            return FixedRidge(self.reg)
        from tacgen_lib.probes.logistic import FixedLogistic

        return FixedLogistic(self.reg, tol=CONTROL_TOL)


def fit_probe(
    X_train: np.ndarray,
    y_train: np.ndarray,
    X_test: np.ndarray,
    settings: ProbeSettings,
    *,
    train_ids: Sequence | np.ndarray | None = None,
    test_ids: Sequence | np.ndarray | None = None,
    batched_cv: bool = True,
) -> FittedProbe:
    """Ridge (CV over ``lambdas``) or logistic (stratified CV over ``C``) on the training rows,
    under ``settings.protocol``: ``standardised`` ridge scales on the training rows first
    (`scaling`), ``mlp2`` fits the 2-layer probe (`mlp`); the logistic probe standardises
    under every protocol but ``mlp2``.

    The number of folds is capped at the number of training rows (ridge) or the smallest
    class count (logistic, inside `probes.fit_logistic`); ``settings.cv_repeats`` draws of
    them are averaged (repeated K-fold; the ``mlp2`` probe's CV draws once). ``batched_cv``
    False fits the logistic CV's folds one at a time by scikit-learn (`fit_logistic`).
    """
    if settings.protocol == "mlp2":
        from tacgen_lib.probes.mlp import FixedMLP, fit_mlp_probe

        mlp = fit_mlp_probe(
            X_train, y_train, settings.kind, settings.mlp, settings.seed, sample_ids=train_ids
        )
        pred = mlp.predict(X_test, sample_ids=test_ids)
        if settings.kind == "logistic":
            pred = np.asarray(pred, dtype=object)
        return FittedProbe(
            pred,
            mlp.weight_decay,
            np.asarray(settings.mlp.weight_decays, dtype=np.float64),
            np.full(len(settings.mlp.weight_decays), np.nan),
            mlp.converged,
            mlp.n_iter,
            fixed_probe=FixedMLP(
                settings.kind, mlp.width, mlp.weight_decay, settings.seed, settings.mlp.max_iter
            ),
            notes=f"width {mlp.width}, weight decay {mlp.weight_decay:g}",
        )
    if settings.kind == "ridge":
        standardised = settings.protocol == "standardised"
        fit_ridge = fit_ridge_probe
        if standardised:  # scikit-learn's scaler is imported only where it is used
            from tacgen_lib.probes.scaling import FixedStandardisedRidge, fit_standardised_ridge

            fit_ridge = fit_standardised_ridge
        probe = fit_ridge(
            X_train,
            y_train,
            settings.lambdas,
            n_folds=min(settings.folds, len(y_train)),
            seed=settings.seed,
            sample_ids=train_ids,
            repeats=settings.cv_repeats,
        )
        grid = probe.predict_grid(X_test, sample_ids=test_ids)  # same decomposition as the CV
        if standardised:
            return FittedProbe(
                grid[probe.best],
                probe.lam,
                probe.lambdas,
                probe.cv_scores,
                True,
                None,
                grid,
                fixed_probe=FixedStandardisedRidge(probe.lam),
            )
        sel = probe.selection
        pred = probe.predict(X_test, sample_ids=test_ids)
        return FittedProbe(pred, probe.lam, sel.lambdas, sel.cv_scores, True, None, grid)
    from tacgen_lib.probes.logistic import fit_logistic

    probe = fit_logistic(
        X_train,
        y_train,
        settings.C,
        settings.seed,
        n_folds=settings.folds,
        sample_ids=train_ids,
        repeats=settings.cv_repeats,
        batched=batched_cv,
    )
    pred = np.asarray(probe.predict(X_test, sample_ids=test_ids), dtype=object)
    return FittedProbe(
        pred,
        probe.C,
        probe.C_grid,
        probe.cv_scores,
        bool(probe.converged and probe.cv_converged),
        int(max(probe.n_iter, probe.cv_max_n_iter)),
    )
