"""The privileged oracle and the vision-only ceiling.

- `oracle_force`: with the true mass, friction and compliance, the oracle grips at the
  geometric centre of the window, sqrt(F_lo F_hi) (the demonstrations' action).
- `vision_ceiling_force`: the best any policy can do from what vision sees. Colour and texture
  are drawn independently of physics, so the visible attribute that matters is the size; for a
  given size, the force maximising the probability of landing inside the window, by Monte Carlo
  over the invisible attributes drawn from the task's own prior (same rejection rule). Its
  success is then measured by physics rollouts like every other condition's.
- `vision_ceiling_success`: the ceiling itself, a number no V-only policy can beat in
  expectation: for each size, the largest probability over forces that the window holds the
  force, averaged over the task's prior of sizes (the sizes of freshly drawn episodes, so the
  rejection rule shapes that prior as it shapes the held-out episodes). It is computed from the
  generative process, not re-scored on the held-out episodes, so it does not carry their
  sampling noise; a V-only policy's held-out success can sit above it by that noise only.
"""

from __future__ import annotations

import numpy as np

from tacgen_lib.policy.settings import PolicySettings
from tacgen_lib.policy.task import GRAVITY, Episode, sample_episodes, window

__all__ = [
    "oracle_force",
    "invisible_prior",
    "vision_ceiling_force",
    "vision_ceiling_success",
]


def oracle_force(ep: Episode, settings: PolicySettings) -> float:
    """Grip force (N per pad) of the privileged oracle: the window's geometric centre."""
    lo, hi = window(ep, settings)
    return float(np.sqrt(lo * hi))


def invisible_prior(
    settings: PolicySettings, size: float, n: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Windows (lo, hi), (n,) each, of objects of `size` whose invisible attributes are drawn
    from the task's prior, with the same feasibility rejection as `sample_episode`."""
    s = settings
    rng = np.random.default_rng([seed, int(round(size * 1e6)), 0xCE1])
    a_peak = np.pi**2 / 2 * s.lift_height / s.lift_time**2
    los, his = [], []
    while sum(len(x) for x in los) < n:
        m = 4 * n
        dens = np.exp(rng.uniform(*np.log(s.density_range), size=m))
        mu = rng.uniform(*s.friction_range, size=m)
        k = np.exp(rng.uniform(*np.log(s.stiffness_range), size=m))
        lo = dens * np.pi / 6 * size**3 * (GRAVITY + a_peak) / (2 * mu)
        hi = k * s.crush_depth
        ok = (hi >= s.min_window_ratio * lo) & (hi <= s.max_window_ratio * lo)
        los.append(lo[ok])
        his.append(hi[ok])
    return np.concatenate(los)[:n], np.concatenate(his)[:n]


def _best_force(settings: PolicySettings, size: float, seed: int) -> tuple[float, float]:
    """(force, P(lo <= force <= hi | size)) maximising that probability over a log grid
    spanning every window of the prior at `size`."""
    lo, hi = invisible_prior(settings, size, settings.ceiling_draws, seed)
    grid = np.exp(np.linspace(np.log(lo.min()), np.log(hi.max()), settings.force_grid * 4))
    p = ((lo[None, :] <= grid[:, None]) & (grid[:, None] <= hi[None, :])).mean(axis=1)
    best = int(np.argmax(p))
    return float(grid[best]), float(p[best])


def vision_ceiling_force(settings: PolicySettings, size: float, seed: int) -> float:
    """The force maximising P(lo <= F <= hi | size) over a log grid spanning every window."""
    return _best_force(settings, size, seed)[0]


def vision_ceiling_success(settings: PolicySettings, seed: int, n_sizes: int = 256) -> float:
    """Expected success of the best force given the size, over the prior of sizes: the mean
    over `n_sizes` freshly drawn episodes (a stream apart from the held-out episodes') of
    max_F P(lo <= F <= hi | size). The maximum is taken on the same Monte Carlo draws it is
    scored on, which can only raise it: the ceiling errs on the side of being a bound."""
    episodes = sample_episodes(settings, seed, n_sizes, prefix="ceiling")
    return float(np.mean([_best_force(settings, ep.size, seed)[1] for ep in episodes]))
