"""The positive control of the regime's curve against the pool size: touch that is a clean
function of the look plus noise at a stated signal-to-noise ratio.

On the natural design at rho = 1 a frame's colour and texture fix its appearance class, which
is its material class (`corpus.sim.samples`): what the look says of the material is what real
touch averaged over a look carries. Real touch carries much else besides (the object's shape
and size dominate its variance), so whether a rung learnt from the pool carries the look's
part into a probe is hard to read from real touch alone. The control replaces each row's touch
by

    T_control(row) = mu(look(row)) + sigma * eps(row),    eps ~ N(0, I),

where mu(look) is the mean real T of the corpus's non-test rows with that look (colour and
texture: `corpus.looks.LOOK_LEVELS`' coarsest level) and sigma is set so that the signal's
variance (that of mu over the non-test rows, summed over T's dimensions) is `snr` times the
noise's (d x sigma^2). Every arm of the regime that reads no generator then reads T_control
where it read real T (rule regime_look_control, `generate.regime.evaluate_regime`), on the
same labelled, pool and test rows: the rungs learnt from the pool must begin to gain as N_P
grows, the effect being built in. A test row's mu is learnt from non-test rows only; its noise
is its own. A row whose look no reference row shows (a small corpus's rare look) takes the mean
of every reference row (no signal), counted in ``n_unseen``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tacgen_lib.generate.blocks import feature_block

__all__ = ["LookControl", "look_control_touch"]


@dataclass(frozen=True)
class LookControl:
    """The control's touch (sample_id -> float64 vector) of every row asked for, its noise
    scale ``sigma``, the signal's variance per dimension, the looks it was built from and the
    signal-to-noise ratio it was built at."""

    t_control: dict[str, np.ndarray]
    sigma: float
    signal_variance: float
    n_looks: int
    snr: float
    n_unseen: int = 0

    def describe(self) -> str:
        return (
            f"T = look mean over {self.n_looks} looks + noise: signal variance "
            f"{self.signal_variance:.4g} per dimension, sigma {self.sigma:.4g}, SNR {self.snr:g}; "
            f"{self.n_unseen} rows of a look no reference row shows (given the reference mean)"
        )


def look_control_touch(
    t_real: Mapping[str, np.ndarray],
    looks: Mapping[str, str] | pd.Series,
    reference: Sequence[str],
    rows: Sequence[str],
    *,
    snr: float,
    seed: int,
) -> LookControl:
    """T_control for `rows`: the mean real T of the `reference` rows (the corpus's non-test
    rows) sharing the row's look, plus Gaussian noise of the scale that makes the signal
    `snr` times the noise in variance (module docstring).

    looks: sample_id -> look key for every reference row and row. The noise is drawn in the
    order of the sorted sample_ids of `rows` from a generator seeded with `seed`, so a row's
    noise does not depend on the order it is asked in. A row whose look no reference row
    shows gets the mean real T of every reference row (counted in ``n_unseen``). Raises
    ValueError when `snr` is not positive, the reference is empty or shows one look, or a
    row has no look or a reference row no real T.
    """
    if not float(snr) > 0.0:
        raise ValueError(f"look_control_touch: snr must be > 0, got {snr}")
    reference = [str(i) for i in reference]
    rows = sorted({str(i) for i in rows})
    if not reference:
        raise ValueError("look_control_touch: no reference rows to learn the look means from")
    look = pd.Series(looks).astype(str)
    missing = [i for i in (*reference, *rows) if i not in look.index]
    if missing:
        raise ValueError(f"look_control_touch: sample_id {missing[0]!r} has no look")
    t_ref = feature_block(t_real, reference, what="look_control_touch")
    keys = look.loc[reference].to_numpy()
    means = pd.DataFrame(t_ref).groupby(keys, sort=True).mean()
    if means.shape[0] < 2:
        raise ValueError(
            f"look_control_touch: the reference rows show one look ({means.index[0]!r}): the "
            "look means carry no signal to build the control from"
        )
    mu_ref = means.loc[keys].to_numpy(np.float64)
    d = mu_ref.shape[1]
    signal_variance = float(mu_ref.var(axis=0).sum() / d)
    if not signal_variance > 0.0:
        raise ValueError(
            "look_control_touch: the look means are all equal (touch that does not differ "
            "between looks): no signal to build the control from"
        )
    sigma = float(np.sqrt(signal_variance / float(snr)))
    noise = np.random.default_rng(int(seed)).standard_normal((len(rows), d))
    overall = t_ref.mean(axis=0)
    row_looks = look.loc[rows].to_numpy()
    seen = np.isin(row_looks, means.index)
    mu_rows = np.tile(overall, (len(rows), 1))
    mu_rows[seen] = means.loc[row_looks[seen]].to_numpy(np.float64)
    t_control = {i: mu_rows[k] + sigma * noise[k] for k, i in enumerate(rows)}
    return LookControl(
        t_control,
        sigma,
        signal_variance,
        int(means.shape[0]),
        float(snr),
        int((~seen).sum()),
    )
