"""How close generated tactile features are to the real ones, row by row and as a distribution:
matched-pair cosine against the off-diagonal mean, a pairing permutation test, and the Fréchet
distance (beside the real train-vs-test distance); and the pairing gap row by row
(`pairing_gaps`), whose mean is matched minus off-diagonal cosine, so that two generators'
gaps on the same test rows can be compared with a paired interval (`gap_interval`).
"""

from __future__ import annotations

import numpy as np
from scipy import linalg

from tacgen_lib.probes.bootstrap import percentile_interval

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


def pairing_gaps(gen: np.ndarray, real: np.ndarray) -> np.ndarray:
    """Per test row i, cos(gen_i, real_i) minus the mean over j != i of cos(gen_i, real_j):
    how much more generated row i resembles its own real row than the others (rows already
    centred). Their mean is `cosine_pairing`'s matched minus off-diagonal cosine."""
    g, r = _unit(np.asarray(gen, np.float64)), _unit(np.asarray(real, np.float64))
    sims = g @ r.T
    n = sims.shape[0]
    if n < 2:
        return np.full(n, np.nan)
    diag = np.diag(sims)
    return diag - (sims.sum(axis=1) - diag) / (n - 1)


def centred_gaps(gen_test: np.ndarray, real_test: np.ndarray, real_train: np.ndarray):
    """`pairing_gaps` of generated and real test rows centred on the real train mean, as
    `fidelity` centres them."""
    centre = np.asarray(real_train, np.float64).mean(axis=0)
    return pairing_gaps(
        np.asarray(gen_test, np.float64) - centre, np.asarray(real_test, np.float64) - centre
    )


def gap_interval(gaps: np.ndarray, resamples: np.ndarray, level: float = 0.95) -> tuple:
    """(mean, lo, hi) of per-row pairing gaps (or a paired difference of two generators' gaps
    on the same rows) with its percentile interval over `resamples` (B, n) of the test rows,
    the fixed-test resamples every probe of the target uses."""
    g = np.asarray(gaps, dtype=np.float64)
    means = g[np.asarray(resamples)].mean(axis=1)
    lo, hi = percentile_interval(means, confidence_level=level)
    return float(g.mean()), lo, hi


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
