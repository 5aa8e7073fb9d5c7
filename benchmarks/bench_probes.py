"""Benchmark one whole probe: lambda grid of 5 + 5-fold CV + 5,000 bootstrap + 200 permutations.

Sizes follow the paper's probe tables: ~1,000 training rows, 459 test rows, frozen features
of 384 (vision) + 768 (tactile) dimensions, concat fusion. Prints wall and CPU times and the
ratio against GridSearchCV(Ridge) and scipy.stats.bootstrap measured in the same run.

Then the logistic controls of a hardness-like probe (binary, 960 x (192 + 192), C = 1,
lbfgs tol 1e-4 as the workflow's controls): label and tactile permutations solved together
by `probes.fit_logistic_batch`, against the per-refit loop (one lbfgs fit at a time, as
`lbfgs.fit_lbfgs_logistic` solves it; timed on
``--logistic-ref`` refits of each control and compared per refit). And the logistic probe's
C selection on that probe's V+T (5 folds x C in {0.1, 1, 10}, tol 1e-6 as the workflow's
probes): folds solved together (`logistic.cv_batches`) against the one-fold-at-a-time loop,
with the CV scores compared. And the generator evaluation's nonlinear V baseline's C selection
(binary, 384 rows of V and its RBF Nystroem map, 5 folds x its C grid of 5, folds with fewer
rows than columns, so never batched): the loop's Newton paths (`newton.newton_logistic_path`)
against one lbfgs fit per fold and C, with the CV scores compared. And single lbfgs fits at the workflow's sizes (32 to 1,408 rows,
two and six classes): the probes' solver (`lbfgs.fit_lbfgs_logistic`) against scikit-learn's
LogisticRegression on the same rows, with iterations and probabilities compared.

    .venv/bin/python benchmarks/bench_probes.py [--repeats 3] [--blas-threads 1]

Not a test: figures depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass

import machine
import numpy as np
import scipy.stats
from machine import parse_args, sized
from sklearn.linear_model import LogisticRegression, Ridge
from sklearn.model_selection import GridSearchCV
from sklearn.preprocessing import StandardScaler
from threadpoolctl import threadpool_info, threadpool_limits

from tacgen_lib.probes import logistic
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap
from tacgen_lib.probes.controls import (
    PairedRows,
    label_permutation_control,
    tactile_permutation_control,
)
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.fusion import fuse
from tacgen_lib.probes.lbfgs import fit_lbfgs_logistic
from tacgen_lib.probes.logistic import FixedLogistic, fit_logistic
from tacgen_lib.probes.refits import Refits
from tacgen_lib.probes.ridge import FixedRidge, fit_ridge_probe


def synthetic_features(n: int, d: int, rng: np.random.Generator) -> np.ndarray:
    """Features with a decaying spectrum and a common offset, like pooled ViT tokens."""
    scales = 3.0 / np.sqrt(1.0 + np.arange(d))
    return rng.standard_normal((n, d)) * scales + rng.standard_normal(d)


#: rows and per-modality width of the hardness-like probe (training rows of the controls and
#: the CV; the controls test on a quarter as many more)
LOGISTIC_ROWS, LOGISTIC_D = sized((960, 192), (48, 8))
#: (rows, features, classes) of the single lbfgs fits
LOGISTIC_FITS = sized(
    ((32, 384, 2), (384, 384, 2), (960, 384, 2), (1408, 192, 6)), ((32, 16, 2), (48, 16, 3))
)


def hardness_like(n: int, d: int = LOGISTIC_D) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(V, T, labels) of a binary probe where both V and T carry the label (seeded)."""
    rng = np.random.default_rng(11)
    v, t = synthetic_features(n, d, rng), synthetic_features(n, d, rng)
    score = v[:, :4].sum(axis=1) + 1.5 * t[:, :4].sum(axis=1) + 2.0 * rng.standard_normal(n)
    return v, t, np.where(score > np.median(score), "hard", "soft").astype(object)


CPU: dict[str, float] = {}  # CPU seconds of the best repeat, by step name


def best_of(fn, repeats: int, name: str = "") -> tuple[float, object]:
    """Best wall time of `repeats` runs (its CPU time is kept in CPU[name]) and the output."""
    best, out = (np.inf, np.inf), None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best = min(best, (time.perf_counter() - t0, time.process_time() - c0))
    CPU[name] = best[1]
    return best[0], out


@dataclass(frozen=True)
class LoopLogistic(FixedLogistic):
    """FixedLogistic forced through the controls' per-refit loop (the reference path)."""

    def batches(self, refits: Refits) -> bool:
        return False


def logistic_controls(args) -> list[tuple]:
    """Rows (name, ours, reference name, reference) for the logistic controls, per refit."""
    n_tr, n_te = LOGISTIC_ROWS, LOGISTIC_ROWS // 4
    v, t, y = hardness_like(n_tr + n_te)
    tr, te = slice(0, n_tr), slice(n_tr, None)
    probe, loop = FixedLogistic(1.0, tol=1e-4), LoopLogistic(1.0, tol=1e-4)
    rows_ = PairedRows(v[tr], t[tr], y[tr], v[te], t[te], y[te])
    b, k = args.logistic_perms, args.logistic_ref
    rows = []
    for name, call in (
        (
            "label",
            lambda p, m: label_permutation_control(
                rows_, probe_v=p, probe_vt=p, metric="accuracy", n_permutations=m, seed=0
            ),
        ),
        (
            "tactile",
            lambda p, m: tactile_permutation_control(
                rows_, probe=p, probe_v=p, metric="accuracy", n_permutations=m, seed=0
            ),
        ),
    ):
        refits = 2 * b if name == "label" else b + 1  # V and V+T refits per permutation
        ref_refits = 2 * k if name == "label" else k + 1
        ours, _ = best_of(lambda c=call: c(probe, b), 1, f"logistic {name}")
        ref, _ = best_of(lambda c=call: c(loop, k), 1, f"ref {name}")
        rows.append(
            (
                f"logistic {name} permutations ({b}), per refit",
                ours / refits,
                f"one-fit lbfgs loop ({k})",
                ref / ref_refits,
            )
        )
    return rows


def logistic_cv() -> tuple:
    """(name, ours, reference name, reference, how they differ) of the hardness-like probe's CV.

    This synthetic design is well conditioned (scikit-learn converges in ~50 iterations), where
    the batched solve gains nothing; the real ViT probes take ~1,000 (README, Probes)."""
    n = LOGISTIC_ROWS
    v, t, y = hardness_like(n)
    x, grid = np.hstack([v, t]), [0.1, 1.0, 10.0]
    ours, batched = best_of(
        lambda: fit_logistic(x, y, grid, seed=42, n_folds=5, repeats=1), 1, "logistic cv"
    )
    batches = logistic.cv_batches
    logistic.cv_batches = lambda shape, folds: False
    try:
        ref, loop = best_of(
            lambda: fit_logistic(x, y, grid, seed=42, n_folds=5, repeats=1), 1, "ref cv"
        )
    finally:
        logistic.cv_batches = batches
    rows = np.abs(batched.cv_scores - loop.cv_scores) * n  # held-out rows, over the 5 folds
    same = (
        f"C {batched.C:g} vs {loop.C:g}; CV scores differ by {rows.max():.0f} held-out row(s)"
        f", iterations {batched.cv_max_n_iter} vs {loop.cv_max_n_iter}"
    )
    name = f"logistic CV 5 folds x 3 C, {n} x {x.shape[1]}"
    return name, ours, "one-fold-at-a-time loop", ref, same


#: rows, V width and RBF map width of the nonlinear baseline's CV (N_L = 384 labelled rows)
NONLINEAR_CV = sized((384, 240, 192), (40, 30, 20))


def nonlinear_cv() -> tuple:
    """(name, ours, reference name, reference, how they differ) of the nonlinear V baseline's
    C selection (`generate.baselines.nonlinear_baseline`'s design, [V, phi(V)]): the CV loop's
    Newton paths against one lbfgs fit per fold and C (`logistic._fold_score`)."""
    from sklearn.kernel_approximation import Nystroem

    n, d, k = NONLINEAR_CV
    v, _, y = hardness_like(n, d)
    z = StandardScaler().fit_transform(v)
    phi = Nystroem(gamma=1.0 / d, n_components=k, random_state=0).fit_transform(z)
    x, grid = np.hstack([v, phi]), np.array([1e-4, 0.01, 0.1, 1.0, 10.0])
    folds = make_folds(n, 5, 42, labels=y)
    assert not logistic.cv_batches(x.shape, folds)
    ours, probe = best_of(
        lambda: fit_logistic(x, y, grid, seed=42, n_folds=5, repeats=1), 1, "nonlinear cv"
    )

    def lbfgs_loop() -> np.ndarray:
        return np.array(
            [
                [logistic._fold_score(x, y, ho, c, 12800, 12800, 1e-6)[0] for c in grid]
                for ho in folds
            ]
        ).mean(axis=0)

    ref, scores = best_of(lbfgs_loop, 1, "ref nonlinear cv")
    rows = np.abs(probe.cv_scores - scores) * n  # held-out rows, over the 5 folds
    same = (
        f"C {probe.C:g} vs {grid[int(np.argmax(scores))]:g}; CV scores differ by "
        f"{rows.max():.0f} held-out row(s); Newton steps at most {probe.cv_max_n_iter}"
    )
    name = f"nonlinear-V CV 5 folds x 5 C, {n} x {x.shape[1]}"
    return name, ours, "one lbfgs fit per fold x C", ref, same


def logistic_fits(repeats: int) -> list[tuple]:
    """(name, ours, reference name, reference, how they differ) of single lbfgs fits at the
    workflow's probe sizes: `lbfgs.fit_lbfgs_logistic` (the probes' solver) against
    scikit-learn's ``LogisticRegression(solver="lbfgs")`` on the same standardised rows."""
    out = []
    for n, d, k in LOGISTIC_FITS:
        v, t, _ = hardness_like(n, d // 2)
        x = StandardScaler().fit_transform(np.hstack([v, t]))
        score = x[:, :6] @ np.linspace(1.0, -1.0, 6) + np.random.default_rng(n).normal(size=n)
        y = np.digitize(score, np.quantile(score, np.linspace(0, 1, k + 1)[1:-1]))
        ours, fit = best_of(
            lambda x=x, y=y: fit_lbfgs_logistic(x, y, 10.0, max_iter=12800, tol=1e-6),
            repeats,
            f"lbfgs {n}",
        )
        ref, sk = best_of(
            lambda x=x, y=y: LogisticRegression(C=10.0, max_iter=12800, tol=1e-6).fit(x, y),
            repeats,
            f"ref lbfgs {n}",
        )
        diff = np.abs(fit.model.predict_proba(x) - sk.predict_proba(x)).max()
        out.append(
            (
                f"logistic fit {n} x {d}, {k} classes, C 10",
                ours,
                "sklearn LogisticRegression",
                ref,
                f"iterations {fit.n_iter} vs {int(sk.n_iter_[0])}, max |d proba| {diff:.1e}",
            )
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-train", type=int, default=1000)
    ap.add_argument("--n-test", type=int, default=459)
    ap.add_argument("--d-v", type=int, default=384)
    ap.add_argument("--d-t", type=int, default=768)
    ap.add_argument("--resamples", type=int, default=5000)
    ap.add_argument("--permutations", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--blas-threads", type=int, default=None, help="cap BLAS threads")
    ap.add_argument("--logistic-perms", type=int, default=50, help="batched logistic refits")
    ap.add_argument("--logistic-ref", type=int, default=5, help="reference loop refits")
    tiny = {"n_train": 40, "n_test": 20, "d_v": 8, "d_t": 8, "resamples": 20, "permutations": 3}
    args = parse_args(ap, {**tiny, "repeats": 1, "logistic_perms": 2, "logistic_ref": 1})
    if args.blas_threads is not None:
        threadpool_limits(args.blas_threads)
    blas = max((p["num_threads"] for p in threadpool_info()), default=0)

    rng = np.random.default_rng(7)
    n = args.n_train + args.n_test
    v = synthetic_features(n, args.d_v, rng)
    t = synthetic_features(n, args.d_t, rng)
    y = v[:, :8].sum(axis=1) + 0.8 * t[:, :8].sum(axis=1) + rng.standard_normal(n)
    tr, te = np.arange(args.n_train), np.arange(args.n_train, n)
    vt = fuse("concat", v, t)
    paired = PairedRows(v[tr], t[tr], y[tr], v[te], t[te], y[te])
    lambdas = np.logspace(-1, 3, 5)
    seed = 0

    def whole_probe():
        pv = fit_ridge_probe(v[tr], y[tr], lambdas, n_folds=5, seed=seed, repeats=1)
        pvt = fit_ridge_probe(vt[tr], y[tr], lambdas, n_folds=5, seed=seed, repeats=1)
        boot = fixed_test_bootstrap(
            y[te], pv.predict(v[te]), pvt.predict(vt[te]), "r2", args.resamples, seed
        )
        return pv, pvt, boot, permutation_control("pcg", pv, pvt)

    def permutation_control(solver, pv=None, pvt=None):
        """The ridge tactile-permutation control at the selected lambdas (kernel path)."""
        pv, pvt = pv or selected[0], pvt or selected[1]
        return tactile_permutation_control(
            paired,
            probe=FixedRidge(pvt.lam, solver=solver),
            probe_v=FixedRidge(pv.lam),
            metric="r2",
            n_permutations=args.permutations,
            seed=seed,
        )

    # pieces, each timed on its own
    t_cv, (pv, pvt) = best_of(
        lambda: (
            fit_ridge_probe(v[tr], y[tr], lambdas, n_folds=5, seed=seed, repeats=1),
            fit_ridge_probe(vt[tr], y[tr], lambdas, n_folds=5, seed=seed, repeats=1),
        ),
        args.repeats,
        "cv",
    )
    selected = (pv, pvt)
    folds = make_folds(args.n_train, 5, seed)
    cv = [(np.setdiff1d(tr, f), f) for f in folds]

    def grid_search():
        a = GridSearchCV(Ridge(), {"alpha": lambdas}, cv=cv).fit(v[tr], y[tr])
        b = GridSearchCV(Ridge(), {"alpha": lambdas}, cv=cv).fit(vt[tr], y[tr])
        return a, b

    t_gs, (gs_v, gs_vt) = best_of(grid_search, args.repeats, "gs")
    assert gs_v.best_params_["alpha"] == pv.lam and gs_vt.best_params_["alpha"] == pvt.lam

    pred_v, pred_vt = pv.predict(v[te]), pvt.predict(vt[te])
    t_boot, boot = best_of(
        lambda: fixed_test_bootstrap(y[te], pred_v, pred_vt, "r2", args.resamples, seed),
        args.repeats,
        "boot",
    )

    def delta_r2(i, axis=-1):
        yi, a, b = y[te][i], pred_v[i], pred_vt[i]
        ss_tot = np.sum((yi - yi.mean(axis=axis, keepdims=True)) ** 2, axis=axis)
        return (np.sum((yi - a) ** 2, axis=axis) - np.sum((yi - b) ** 2, axis=axis)) / ss_tot

    t_sp, sp = best_of(
        lambda: scipy.stats.bootstrap(
            (np.arange(args.n_test),),
            delta_r2,
            n_resamples=args.resamples,
            method="percentile",
            vectorized=True,
            rng=np.random.default_rng(seed),
        ),
        args.repeats,
        "scipy",
    )
    t_ctrl, ctrl = best_of(lambda: permutation_control("pcg"), 1, "ctrl")
    t_chol, chol = best_of(lambda: permutation_control("cholesky"), 1, "chol")
    assert np.allclose(chol["deltas"], ctrl["deltas"], rtol=1e-6, atol=1e-9)
    t_all, _ = best_of(whole_probe, args.repeats, "all")

    print(f"machine: {machine.describe()}")
    print(
        f"BLAS threads {blas}; n_train={args.n_train} n_test={args.n_test} "
        f"d={args.d_v}+{args.d_t}; lambdas={np.round(lambdas, 3).tolist()}"
    )
    print(
        f"selected lambda V={pv.lam:g} (CV solvers {pv.selection.solver[0]}) "
        f"V+T={pvt.lam:g} ({pvt.selection.solver[0]}); GridSearchCV agrees"
    )
    print(
        f"Delta R2 = {boot['delta']:.4f}  CI [{boot['ci_low']:.4f}, {boot['ci_high']:.4f}]  "
        f"(scipy percentile CI [{sp.confidence_interval.low:.4f}, "
        f"{sp.confidence_interval.high:.4f}]);  Delta_ctrl = {ctrl['delta_ctrl']:.4f}"
    )
    rows = [
        ("CV lambda select + refit (V, V+T)", t_cv, "cv", "GridSearchCV(Ridge) x2", t_gs),
        (f"fixed_test_bootstrap ({args.resamples})", t_boot, "boot", "scipy.stats.bootstrap", t_sp),
        (
            f"tactile permutations ({args.permutations}), PCG",
            t_ctrl,
            "ctrl",
            "Cholesky/permutation",
            t_chol,
        ),
        ("whole probe (all of the above)", t_all, "all", "", np.nan),
    ]
    head = f"{'step':46s} {'ours [s]':>9s} {'cpu [s]':>8s} {'reference':>24s} {'ref [s]':>8s}"
    print(f"{head} {'ref/ours':>8s}")
    for name, ours, key, ref_name, ref in rows:
        ratio = f"{ref / ours:8.2f}" if np.isfinite(ref) else ""
        ref_s = f"{ref:8.3f}" if np.isfinite(ref) else ""
        print(f"{name:46s} {ours:9.3f} {CPU[key]:8.3f} {ref_name:>24s} {ref_s:>8s} {ratio}")
    if args.logistic_perms > 0:
        for name, ours, ref_name, ref in logistic_controls(args):
            print(f"{name:46s} {ours:9.4f} {'':8s} {ref_name:>24s} {ref:8.4f} {ref / ours:8.1f}")
        for name, ours, ref_name, ref, same in [
            logistic_cv(),
            nonlinear_cv(),
            *logistic_fits(args.repeats),
        ]:
            print(
                f"{name:46s} {ours:9.4f} {'':8s} {ref_name:>24s} {ref:8.4f} {ref / ours:8.1f}"
                f"  ({same})"
            )
    print(
        f"PCG: {ctrl['solver']}; load average during run: {os.getloadavg()[0]:.1f} "
        "(CPU time sums BLAS threads)"
    )
    print("target: whole probe <= 1 s on 2 cores")


if __name__ == "__main__":
    main()
