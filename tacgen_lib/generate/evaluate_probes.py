"""The probes of one target in a generator's evaluation (`evaluate.evaluate_generator`): its V
and T_real blocks and one draw of its fixed-test resamples (`target_probes`), the probe fit, the
paired bootstrap with the family-wise interval of a generated row (`family_interval`), and the
per-cell fit that reuses the logistic C chosen on the reference cell (`TargetProbes.fit_cell`;
the reuse is the `evaluate` module docstring's).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from tacgen_lib.generate.baselines import TargetSpec
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.probes.bootstrap import (
    fixed_test_bootstrap,
    percentile_interval,
    resample_indices,
)
from tacgen_lib.probes.fit import FittedProbe, fit_probe
from tacgen_lib.probes.logistic import FixedLogistic
from tacgen_lib.probes.rows import FamilyRows
from tacgen_lib.probes.settings import ProbeSettings

#: ``reg_source`` of a probe whose regulariser was chosen by its own CV / taken from the
#: reference cell's CV of the same input kind (logistic t_gen and t_gen_shuffled only).
REG_CV, REG_REFERENCE = "cv", "reference cell"


#: The family-wise error rate of the generated-touch rows a page compares (two-sided).
FAMILY_ALPHA = 0.05


def family_interval(deltas: np.ndarray, size: int) -> tuple[float, float]:
    """The Bonferroni interval of one of `size` compared bootstrap differences: the central
    1 - `FAMILY_ALPHA` / size percentile interval (`bootstrap.percentile_interval`). All
    `size` intervals hold together with probability at least 1 - `FAMILY_ALPHA`; at size 1 it
    is the 95 % CI. Its lower bound above 0 is a gain read family-wise, the first step of
    Holm's procedure (`probes.multiplicity.holm`) on the same comparisons."""
    if size < 1:
        raise ValueError(f"family_interval: family size must be at least 1, got {size}")
    return percentile_interval(deltas, confidence_level=1.0 - FAMILY_ALPHA / size)


@dataclass
class TargetProbes:
    """One target's probes: its rows and probe settings, the V and T_real blocks of its train
    and test rows, its fixed-test resamples (one draw shared by every bootstrap of the target),
    the size of its generated rows' family, and the logistic C chosen on the reference cell
    per input kind (`fit_cell`)."""

    name: str
    rows: FamilyRows
    ps: ProbeSettings
    v_tr: np.ndarray
    v_te: np.ndarray
    t_tr: np.ndarray
    t_te: np.ndarray
    resamples: np.ndarray
    family: int
    chosen: dict[str, float] = field(default_factory=dict)

    def fit(self, x_tr: np.ndarray, x_te: np.ndarray) -> FittedProbe:
        """The probes stage's probe fitted on the train rows' `x_tr`, predicting `x_te`."""
        rows = self.rows
        return fit_probe(
            x_tr, rows.y_train, x_te, self.ps, train_ids=rows.train_ids, test_ids=rows.test_ids
        )

    def boot(self, pred_a: np.ndarray, pred_b: np.ndarray, generated: bool = False) -> dict:
        """The paired fixed-test bootstrap of `pred_b` against `pred_a` on the target's
        resamples; a generated row's also carries its family-wise interval (`family_interval`)."""
        ps, rows = self.ps, self.rows
        out = fixed_test_bootstrap(
            rows.y_test,
            pred_a,
            pred_b,
            ps.metric,
            n_resamples=ps.bootstrap,
            seed=ps.seed,
            indices=self.resamples,
            sample_ids=rows.test_ids,
            return_distribution=generated,
        )
        if generated:
            out["ci_low_fw"], out["ci_high_fw"] = family_interval(out.pop("deltas"), self.family)
        return out

    def fit_cell(
        self, inp: str, x_tr: np.ndarray, x_te: np.ndarray
    ) -> tuple[np.ndarray, float, str]:
        """(test predictions, regulariser, its source) of one cell's V + x probe."""
        if self.ps.kind == "logistic" and inp in self.chosen:
            # lbfgs from max_iter = the cap at once: the iterates do not depend on max_iter,
            # so a fit that converges gives the probe's own fit without its restarts
            # (fit_logistic_once doubles max_iter from 200 and starts again from zero)
            cap = FixedLogistic.max_iter_cap
            fixed = FixedLogistic(self.chosen[inp], max_iter=cap, max_iter_cap=cap)
            pred = np.asarray(fixed.fit_predict(x_tr, self.rows.y_train, x_te), dtype=object)
            return pred, self.chosen[inp], REG_REFERENCE
        probe = self.fit(x_tr, x_te)
        if self.ps.kind == "logistic":
            self.chosen[inp] = float(probe.reg)
        return probe.pred_test, float(probe.reg), REG_CV


def target_probes(
    spec: TargetSpec,
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    family: int,
) -> TargetProbes:
    """The probes of `spec`: its V and T_real blocks and one draw of its fixed-test resamples."""
    rows, ps = spec.rows, spec.settings
    v_tr, v_te = feature_block(vision, rows.train_ids), feature_block(vision, rows.test_ids)
    t_tr, t_te = feature_block(t_real, rows.train_ids), feature_block(t_real, rows.test_ids)
    # one draw of the 5,000 test resamples, shared by every bootstrap of this target
    resamples = resample_indices(len(rows.y_test), ps.bootstrap, ps.seed, strata=rows.strata_test)
    return TargetProbes(spec.name, rows, ps, v_tr, v_te, t_tr, t_te, resamples, family)
