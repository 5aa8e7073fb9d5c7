"""The probes of the probes stage on one simulation setting's reduced corpus.

`probe_metrics` fits the family's probe (`tacgen_lib.probes.protocol.fit_probe`: the same ridge
or logistic CV as rule probe) on V and on V+T (concat) and reports the score of V+T with its
fixed-test bootstrap CI (`tacgen_lib.cost.scores.score_ci`) and Delta = score(V+T) - score(V)
with the paper's CI (`tacgen_lib.probes.bootstrap.fixed_test_bootstrap`).
"""

from __future__ import annotations

import numpy as np

from tacgen_lib.cost.knob_metrics import PERCENTILE_CI, metric_row, probe_metric_ids
from tacgen_lib.cost.scores import score_ci
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap
from tacgen_lib.probes.fusion import fuse
from tacgen_lib.probes.protocol import FamilyRows, ProbeSettings, fit_probe

__all__ = ["probe_metrics"]


def probe_metrics(
    rows: FamilyRows,
    v: tuple[np.ndarray, np.ndarray],
    t: tuple[np.ndarray, np.ndarray],
    settings: ProbeSettings,
) -> list[dict]:
    """The family's probe on V and on V+T (concat), both fitted on the training rows as the
    probes stage fits them (`fit_probe`): two rows of `METRIC_COLUMNS`,
    "<target> <metric> V+T" (with `score_ci`) and "<target> Δ<metric> V+T − V" (with
    `fixed_test_bootstrap`), both on `settings.bootstrap` resamples at `settings.seed`.

    v, t: (train, test) feature arrays of the vision and tactile features, rows in `rows`'
    train / test order.
    """
    metric = settings.metric
    fits = {}
    for name, (x_tr, x_te) in (("V", v), ("V+T", (fuse("concat", v[0], t[0]),
                                                   fuse("concat", v[1], t[1])))):  # fmt: skip
        fits[name] = fit_probe(x_tr, rows.y_train, x_te, settings,
                               train_ids=rows.train_ids, test_ids=rows.test_ids)  # fmt: skip
    b, seed = settings.bootstrap, settings.seed
    s, lo, hi = score_ci(metric, rows.y_test, fits["V+T"].pred_test, n_resamples=b, seed=seed)
    boot = fixed_test_bootstrap(rows.y_test, fits["V"].pred_test, fits["V+T"].pred_test, metric,
                                n_resamples=b, seed=seed, sample_ids=rows.test_ids)  # fmt: skip
    score_id, delta_id = probe_metric_ids(rows.target, metric)
    how = PERCENTILE_CI.format(b=b)
    return [
        metric_row(score_id, s, lo, hi, how),
        metric_row(delta_id, boot["delta"], boot["ci_low"], boot["ci_high"], how),
    ]
