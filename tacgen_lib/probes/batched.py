"""Batched solvers: B refits of one probe solved together (the controls' permutations,
resamples and random draws).

This module owns the solvers, not the objectives:

- `fit_logistic_batch`: L-BFGS for B logistic problems (`objective.LogisticObjective`) in
  preconditioned coordinates (`block_basis`, `Preconditioner`), with a backtracking line
  search along the precomputed margin direction;
- `concat_ridge_permuted`: ridge on [V, P_j T] for B row permutations P_j in the dual (kernel)
  form, by batched preconditioned CG (`pcg_permuted`, deflated with `top_eigenpairs`) with
  a Cholesky factorisation for any permutation that does not converge.

Each is tested equal to the one-problem-at-a-time reference (scikit-learn's lbfgs, one
Cholesky per permutation); which controls may use them is decided by the probes
(`FixedRidge.batches`, `FixedLogistic.batches`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg

from tacgen_lib.probes.blas_threads import single_blas_thread
from tacgen_lib.probes.objective import DesignBlock, LogisticObjective

__all__ = [
    "BlockBasis",
    "LogisticBatch",
    "Preconditioner",
    "block_basis",
    "concat_ridge_permuted",
    "fit_logistic_batch",
    "lbfgs_direction",
    "pcg_permuted",
    "top_eigenpairs",
]

_EPS = np.finfo(np.float64).eps
#: The seed of `top_eigenpairs`' Gaussian sketch in the permuted ridge's preconditioner
#: (`pcg_permuted`): it sets the iteration count, never the solution.
_SKETCH_SEED = 0


# --------------------------------------------------------------------------- logistic


@dataclass(frozen=True)
class LogisticBatch:
    """Outcome of `fit_logistic_batch`: B fitted problems."""

    classes: np.ndarray  # (K,) class labels, sorted
    coef: np.ndarray  # (B, p, K') with K' = 1 for two classes (sigmoid), else K
    intercept: np.ndarray  # (B, K')
    n_iter: np.ndarray  # (B,) L-BFGS iterations to convergence (or the cap)
    converged: np.ndarray  # (B,) max |gradient| <= tol

    def decision(self, blocks: Sequence[DesignBlock]) -> np.ndarray:
        """(B, m, K') decision values on test blocks (same layout as the training blocks)."""
        out, start = 0.0, 0
        for blk in blocks:
            out = out + blk.margins(self.coef[:, start : start + blk.dim])
            start += blk.dim
        return out + self.intercept[:, None, :]

    def predict(self, blocks: Sequence[DesignBlock]) -> np.ndarray:
        """(B, m) predicted labels; ties as scikit-learn (decision > 0; first argmax)."""
        d = self.decision(blocks)
        idx = (d[:, :, 0] > 0).astype(int) if d.shape[2] == 1 else d.argmax(axis=2)
        return self.classes[idx]


@dataclass(frozen=True)
class BlockBasis:
    """A symmetric change of variables w = T gamma for one block, kept in whichever form is
    cheaper to apply: T = identity_scale I + vecs diag(coef) vecs^T (low rank) or dense."""

    identity_scale: float
    vecs: np.ndarray | None = None  # (d, r)
    coef: np.ndarray | None = None  # (r,)
    dense: np.ndarray | None = None  # (d, d)
    dim: int = 0

    def apply(self, x: np.ndarray) -> np.ndarray:
        """T x for x (d, m): one GEMM (dense) or two thin ones (low rank)."""
        if self.dense is not None:
            return self.dense @ x
        out = self.identity_scale * x
        if self.vecs is not None:
            out += self.vecs @ (self.coef[:, None] * (self.vecs.T @ x))
        return out


def block_basis(blk: DesignBlock, curvature: float, pen: float) -> BlockBasis:
    """Change of variables w = T gamma (d x d) that makes the block's Hessian ~ I at w = 0.

    From the block's scatter (shared data, standardised by its first problem's affine):
    T = V diag(h^-1/2) V^T with h = curvature * s^2 / n + pen and Z^T Z = V diag(s^2) V^T:
    symmetric (a rotation, a scaling and the rotation back), so the penalty stays diagonal.
    Directions whose loss curvature is below 1e-3 of the penalty get h = pen exactly (a
    relative change of their scaling below half of 1e-3; any SPD T gives the same optimum): with fewer
    rows than columns that leaves T = pen^-1/2 I plus a rank <= n term, applied in about
    2 n / d of a dense product's time. Private blocks (random features, standardised
    columns) are only scaled.
    """
    d = blk.dim
    if blk.data.ndim == 3:
        return BlockBasis(1.0 / np.sqrt(curvature + pen), dim=d)
    off = np.zeros(d) if blk.offset is None else np.atleast_2d(blk.offset)[0]
    sc = np.ones(d) if blk.scale is None else np.atleast_2d(blk.scale)[0]
    z = (blk.data - off) / sc
    e, v = scipy.linalg.eigh(z.T @ z, driver="evd", check_finite=False)
    loss_curv = curvature * np.maximum(e, 0.0) / z.shape[0]
    keep = loss_curv > 1e-3 * pen
    if 2 * keep.sum() < d:
        inv_root = 1.0 / np.sqrt(loss_curv[keep] + pen)
        return BlockBasis(1.0 / np.sqrt(pen), v[:, keep], inv_root - 1.0 / np.sqrt(pen), dim=d)
    return BlockBasis(0.0, dense=(v / np.sqrt(loss_curv + pen)) @ v.T, dim=d)


def lbfgs_direction(
    g: np.ndarray, s_hist: list[np.ndarray], y_hist: list[np.ndarray], rho: list[np.ndarray]
) -> np.ndarray:
    """L-BFGS search direction -H g for B problems at once (the two-loop recursion, Nocedal &
    Wright alg. 7.4), with the initial Hessian scaled by s^T y / y^T y of the newest pair."""
    q = -g
    alphas = []
    for s_, y_, r_ in zip(reversed(s_hist), reversed(y_hist), reversed(rho), strict=True):
        a = r_ * np.einsum("bi,bi->b", s_, q)
        q -= a[:, None] * y_
        alphas.append(a)
    if s_hist:
        sy = np.einsum("bi,bi->b", s_hist[-1], y_hist[-1])
        yy = np.einsum("bi,bi->b", y_hist[-1], y_hist[-1])
        q *= np.where(yy > 0, sy / np.where(yy > 0, yy, 1.0), 1.0)[:, None]
    for s_, y_, r_, a in zip(s_hist, y_hist, rho, reversed(alphas), strict=True):
        q += (a - r_ * np.einsum("bi,bi->b", y_, q))[:, None] * s_
    return q


@dataclass(frozen=True)
class Preconditioner:
    """The change of variables w = T gamma of every block (`block_basis`), applied to B
    problems' coefficients (B, p, K) with one product per block (d x (B K)); a broadcast
    matmul would run B small products, far slower here."""

    bases: list[BlockBasis]
    n_problems: int
    k: int

    def apply(self, x: np.ndarray) -> np.ndarray:
        """T (symmetric) applied block-wise to x (B, p, K)."""
        b, k = self.n_problems, self.k
        cut = np.cumsum([t.dim for t in self.bases])[:-1]
        out = []
        for t, part in zip(self.bases, np.split(x, cut, axis=1), strict=True):
            d = part.shape[1]
            flat = part.transpose(1, 0, 2).reshape(d, b * k)
            out.append(t.apply(flat).reshape(d, b, k).transpose(1, 0, 2))
        return np.concatenate(out, axis=1)


def fit_logistic_batch(
    blocks: Sequence[DesignBlock],
    y: np.ndarray,
    C: float,
    *,
    sample_weight: np.ndarray | None = None,
    classes: np.ndarray | None = None,
    tol: float = 1e-6,
    max_iter: int = 12800,
    memory: int = 10,
) -> LogisticBatch:
    """B independent L2-regularised logistic regressions, solved together by L-BFGS.

    Problem b minimises scikit-learn's lbfgs objective
    ``sum_i s_bi loss(x_bi, y_bi) / S_b + ||coef_b||^2 / (2 C S_b)`` (S_b = sum_i s_bi;
    intercept unpenalised; sigmoid loss for two classes, multinomial softmax with K
    coefficient vectors otherwise), on the design [blocks] (already standardised, e.g.
    `standardise_block`). y: (B, n) or (n,) labels; sample_weight (B, n) row multiplicities.
    Stops each problem when max |gradient of that objective| <= tol (scikit-learn's
    ``pgtol``, in the same coordinates), when a step reduces it by no more than rounding
    (scipy's ``ftol = 64 eps``, which scikit-learn also passes), or at max_iter. The L2 term makes the objective
    strictly convex with a finite minimiser, also for linearly separable classes. Every
    problem must hold every class (a bootstrap resample that misses one is refitted alone
    by the caller: scikit-learn then fits fewer classes).

    Speed: L-BFGS runs in preconditioned coordinates w = T gamma (`block_basis`: each
    block's scatter rotated and scaled so the Hessian at 0 is ~I), which cuts the iterations
    several-fold against scikit-learn's lbfgs on standardised features; one (n, d) x (d, B K)
    GEMM per block gives all margins and one all gradients; the line search moves along the
    precomputed margin direction, so trial steps cost no product.
    """
    objective = LogisticObjective.of(blocks, y, C, sample_weight=sample_weight, classes=classes)
    b, n, k = objective.n_problems, objective.n_rows, objective.k
    p = sum(objective.dims)
    curv = objective.curvature
    basis = Preconditioner(
        [block_basis(blk, curv, float(objective.penalty.mean())) for blk in blocks], b, k
    )
    t_int = 1.0 / np.sqrt(curv)  # intercept scaling

    def gradient(w: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(gradient in the original coordinates (B, pK + K), in gamma coordinates)."""
        gw, gc = objective.gradient(w, m)
        g_orig = np.concatenate([gw.reshape(b, -1), gc], axis=1)
        # gradient in gamma coordinates: T^T gw, and T^T = T
        g_gam = np.concatenate([basis.apply(gw).reshape(b, -1), t_int * gc], axis=1)
        return g_orig, g_gam

    gam = np.zeros((b, p * k + k))
    w = np.zeros((b, p, k))
    m = np.zeros((b, n, k))
    f = objective.value(w, m)
    g_orig, g = gradient(w, m)
    s_hist: list[np.ndarray] = []
    y_hist: list[np.ndarray] = []
    rho: list[np.ndarray] = []
    n_iter = np.zeros(b, dtype=np.int64)
    done = np.abs(g_orig).max(axis=1) <= tol
    for it in range(1, max_iter + 1):
        if done.all():
            break
        q = lbfgs_direction(g, s_hist, y_hist, rho)
        q[done] = 0.0
        dw = basis.apply(q[:, : p * k].reshape(b, p, k))  # gamma step -> coefficient step
        dm = objective.margins(dw) + (t_int * q[:, p * k :])[:, None, :]
        slope = np.einsum("bi,bi->b", g, q)
        step = np.where(done, 0.0, 1.0)
        todo = ~done  # backtracking (Armijo); margins are linear in the step
        for _ in range(60):
            trial = objective.value(w + step[:, None, None] * dw, m + step[:, None, None] * dm)
            todo &= ~(trial <= f + 1e-4 * step * slope)
            if not todo.any():
                break
            step = np.where(todo, 0.5 * step, step)
        gam += step[:, None] * q
        w = w + step[:, None, None] * dw
        m = m + step[:, None, None] * dm
        f_old, f = f, objective.value(w, m)
        g_orig, g_new = gradient(w, m)
        s_vec, y_vec = step[:, None] * q, g_new - g
        sy = np.einsum("bi,bi->b", s_vec, y_vec)
        good = sy > 1e-12 * np.einsum("bi,bi->b", y_vec, y_vec)  # strictly convex: > 0
        s_hist.append(np.where(good[:, None], s_vec, 0.0))
        y_hist.append(np.where(good[:, None], y_vec, 0.0))
        rho.append(np.where(good, 1.0 / np.where(good, sy, 1.0), 0.0))
        if len(s_hist) > memory:
            s_hist.pop(0), y_hist.pop(0), rho.pop(0)
        g = g_new
        n_iter[~done] = it
        # scipy's L-BFGS-B rules, as scikit-learn runs them: projected gradient <= tol, or a
        # relative reduction of f at rounding level (ftol = 64 eps; the gradient then cannot
        # be resolved further -- reached only with tol near 1e-10)
        flat_f = f_old - f <= 64 * _EPS * np.maximum(np.maximum(np.abs(f_old), np.abs(f)), 1.0)
        done |= (np.abs(g_orig).max(axis=1) <= tol) | flat_f
    return LogisticBatch(objective.classes, w, t_int * gam[:, p * k :], n_iter, done)


# --------------------------------------------------------------------------- ridge


def top_eigenpairs(x: np.ndarray, k: int, seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Approximate top-k eigenpairs of the centred Gram x @ x.T (x: n x p), and its trace.

    Randomised subspace iteration (two power steps, 16 extra columns, seeded Gaussian sketch)
    followed by Rayleigh-Ritz: returns Ritz values (descending, positive) and ORTHONORMAL Ritz
    vectors (n, k'). They only shape the PCG preconditioner, which stays symmetric positive
    definite for any orthonormal basis and positive values, so their accuracy sets the
    iteration count, never the solution. Costs ~10 n p (k + 16) flops instead of an eigh.
    """
    n, p = x.shape
    trace = float(np.einsum("ij,ij->", x, x))
    k = min(k, n - 1, p)
    if k <= 0:
        return np.zeros(0), np.zeros((n, 0)), trace
    sketch = np.random.default_rng(seed).standard_normal((p, min(k + 16, n, p)))
    q = np.linalg.qr(x @ sketch)[0]
    for _ in range(2):  # power steps sharpen the top of the spectrum
        q = np.linalg.qr(x @ (x.T @ q))[0]
    b = x.T @ q  # (p, l): Q^T (x x^T) Q = b^T b
    e, z = np.linalg.eigh(b.T @ b)
    e, z = e[::-1][:k], z[:, ::-1][:, :k]
    keep = e > max(n, p) * np.finfo(np.float64).eps * max(float(e[0]), 0.0)
    return e[keep], q @ z[:, keep], trace


def pcg_permuted(
    kv: np.ndarray,
    kt: np.ndarray,
    vc: np.ndarray,
    tc: np.ndarray,
    yc: np.ndarray,
    lam: float,
    perm: np.ndarray,
    tol: float,
    max_iter: int,
    deflate: int = 64,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Batched preconditioned CG for (Kv + P_j Kt P_j^T + lam I) alpha_j = yc, all j at once.

    The operator is applied to all permutations with two (B, n) x (n, n) products. The
    preconditioner keeps the top ``deflate`` eigen-directions of both blocks exactly and
    replaces the rest of each block by its average eigenvalue:
    M_j = c0 I + W_j diag(e_v, e_t) W_j^T, W_j = [U_v, P_j U_t] (n x (m + k)),
    c0 = lam + (rest of tr Kv + rest of tr Kt) / (n - 1). It is inverted by Woodbury with a
    (m + k) capacitance whose only per-permutation block is C_j = U_v^T P_j U_t (m x k),
    eliminated through its k x k Schur complement. M_j is symmetric positive definite for any
    such choice, so the iteration converges to the same solution whatever its quality;
    quality only sets the iteration count (measured at n = 1000, d = 384 + 768, lambda = 100:
    47 iterations with the vision block alone, 18 with 64 + 64 directions).
    Returns (alphas (B, n), converged (B,), iterations): converged means relative
    residual <= tol within max_iter.
    """
    n, b = yc.size, perm.shape[0]
    e_v, u_v, tr_v = top_eigenpairs(vc, deflate, _SKETCH_SEED)
    e_t, u_t, tr_t = top_eigenpairs(tc, deflate, _SKETCH_SEED)
    c0 = lam + max(tr_v - e_v.sum() + tr_t - e_t.sum(), 0.0) / max(n - 1, 1)
    rows = n * np.arange(b)[:, None]
    fwd = perm + rows  # flat gather indices: np.take is several times faster than
    inv = np.argsort(perm, axis=1) + rows  # take_along_axis for (B, n) row permutations

    def permute(x: np.ndarray) -> np.ndarray:  # row j: P_j x_j, i.e. x_j[perm_j]
        return np.take(x, fwd)

    def unpermute(x: np.ndarray) -> np.ndarray:  # row j: P_j^T x_j
        return np.take(x, inv)

    # capacitance G_j = [[dv, C_j], [C_j^T, dt]] with dv, dt diagonal; Schur S_j = dt - C^T C/dv
    dv = c0 / e_v + 1.0
    dt = c0 / e_t + 1.0
    cross = np.empty((b, e_v.size, e_t.size))
    with single_blas_thread():  # B small products: threads only add synchronisation
        for j in range(b):  # U_v^T P_j U_t = U_v^T (rows perm_j of U_t)
            cross[j] = u_v.T @ u_t[perm[j]]
        schur = -np.matmul((cross / dv[:, None]).transpose(0, 2, 1), cross)
        schur[:, np.arange(e_t.size), np.arange(e_t.size)] += dt
        schur_inv = np.linalg.inv(schur)
    kvl = kv.copy()
    kvl[np.diag_indices_from(kvl)] += lam

    def precondition(r: np.ndarray) -> np.ndarray:
        a = r @ u_v  # (B, m) = U_v^T r
        t = unpermute(r) @ u_t  # (B, k) = (P U_t)^T r
        t = t - np.matmul((a / dv)[:, None, :], cross)[:, 0]
        s_t = np.matmul(schur_inv, t[:, :, None])[:, :, 0]
        s_v = (a - np.matmul(cross, s_t[:, :, None])[:, :, 0]) / dv
        return (r - s_v @ u_v.T - permute(s_t @ u_t.T)) / c0

    def operator(x: np.ndarray) -> np.ndarray:
        return x @ kvl + permute(unpermute(x) @ kt)

    b_norm = np.linalg.norm(yc)
    x = np.zeros((b, n))
    r = np.broadcast_to(yc, x.shape).copy()
    if b_norm == 0.0:
        return x, np.ones(b, dtype=bool), 0
    zr = precondition(r)
    d = zr.copy()
    rz = np.einsum("ij,ij->i", r, zr)
    done = np.zeros(b, dtype=bool)
    it = 0
    while it < max_iter:
        it += 1
        ad = operator(d)
        step = np.where(done, 0.0, rz / np.einsum("ij,ij->i", d, ad))
        x += step[:, None] * d
        r -= step[:, None] * ad
        done |= np.linalg.norm(r, axis=1) <= tol * b_norm
        if done.all():
            break
        zr = precondition(r)
        rz_new = np.einsum("ij,ij->i", r, zr)
        d = zr + (rz_new / rz)[:, None] * d
        rz = rz_new
    return x, done, it


def concat_ridge_permuted(
    v_tr: np.ndarray,
    t_tr: np.ndarray,
    y_tr: np.ndarray,
    v_te: np.ndarray,
    t_te: np.ndarray,
    lam: float,
    perm_tr: np.ndarray,
    perm_te: np.ndarray | None = None,
    *,
    solver: Literal["pcg", "cholesky"] = "pcg",
    tol: float = 1e-10,
    max_iter: int = 100,
    deflate: int = 64,
) -> tuple[np.ndarray, dict]:
    """Test predictions (B, m) of ridge on [V, T[perm_tr]] for every training permutation
    (dual form), and solver counts (PCG iterations, permutations solved by Cholesky).

    perm_te: (B, m) permutations of the test T rows, or None (the tactile-permutation
    control's case: test row i keeps its own t_te[i]).

    Kernel form: the centred Gram of [V, P T] is Kv + P Kt P^T (a row permutation keeps the
    column means), so no feature product is recomputed per permutation. Solved for all
    permutations at once by batched PCG (`pcg_permuted`); permutations that do not reach
    the tolerance within max_iter (small lambda: ill-conditioned) are solved by Cholesky,
    as is everything with solver="cholesky". ``deflate``: eigen-directions per block kept
    exactly by the PCG preconditioner.
    """
    mv, mt = v_tr.mean(axis=0), t_tr.mean(axis=0)
    vc, tc = v_tr - mv, t_tr - mt
    kv, kt = vc @ vc.T, tc @ tc.T
    ym = y_tr.mean()
    yc = y_tr - ym
    if solver == "pcg":
        alphas, done, iters = pcg_permuted(kv, kt, vc, tc, yc, lam, perm_tr, tol, max_iter, deflate)
    else:
        alphas, done = np.empty((perm_tr.shape[0], yc.size)), np.zeros(perm_tr.shape[0], bool)
        iters = 0
    info = {"pcg_iterations": iters, "cholesky_solves": int((~done).sum())}
    kv[np.diag_indices_from(kv)] += lam
    for j in np.flatnonzero(~done):  # one n x n factorisation per remaining permutation
        p = perm_tr[j]
        gram = kv + kt[np.ix_(p, p)]
        factor = scipy.linalg.cho_factor(gram, lower=True, check_finite=False, overwrite_a=True)
        alphas[j] = scipy.linalg.cho_solve(factor, yc, check_finite=False)
    z = np.zeros_like(alphas)  # z[j, p_j[i]] = alpha[j, i]  =>  Kt[:, p] @ a == Kt @ z
    np.put_along_axis(z, perm_tr, alphas, axis=1)
    kvx = (v_te - mv) @ vc.T  # (m, n)
    ktx = (t_te - mt) @ tc.T
    pv = alphas @ kvx.T  # (B, m)
    pt = z @ ktx.T  # (B, m): test row i paired with its own t_te[i] ...
    if perm_te is not None:  # ... or with t_te[perm_te[j, i]]
        pt = np.take_along_axis(pt, perm_te, axis=1)
    return ym + pv + pt, info
