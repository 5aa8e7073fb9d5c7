"""What V sees: how well the frozen vision features decode each factor a simulated frame shows.

For every simulated corpus, each visible factor (`corpus.looks.visible_factors`: colour,
texture, shape, size third and, on the natural design, the appearance class) is decoded from V
by a linear probe (the probes stage's logistic probe, C by CV) and a nonlinear probe (an
RBF-kernel SVM on standardised V, C and gamma by CV, `small_probes.fit_kernel_probe`), and each
factor the gate reads also by the probes stage's 2-layer probe (``mlp2``, `probes.mlp`: width
and weight decay by CV, config ``probes.robustness.mlp``), each fitted on every non-test row of
the corpus and scored on its test split with a fixed-test bootstrap CI beside the majority
class's share of the test rows. Why a third probe: the appearance class is a function of two
factors, (colour index + texture index) mod 6, so each class is a union of colour x texture
combinations scattered through V; a kernel of one bandwidth over every dimension of V,
shape, size and pose included, reads such a class worse than a network that learns which
directions of V matter, even where V holds colour and texture both.

It is the gate for reading any result that depends on what V sees: the regime's generator can
pass on only what V holds, so where V does not decode the appearance class the regime cannot
say whether generated touch helps (`visibility_gate`). A factor with one level among a
corpus's train rows, or with a test level its train rows lack (the controlled corpus's
held-out scale), has nothing a probe could decode and gets no row.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from tacgen_lib.corpus.looks import FACTORS
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.small_probes import fit_kernel_probe, fit_small_mlp, fit_small_probe
from tacgen_lib.io.schema import SchemaSettings, schema_fields
from tacgen_lib.probes.bootstrap import resample_indices, score_interval
from tacgen_lib.probes.metrics import score
from tacgen_lib.probes.settings import MLPGrid, ProbeSettings
from tacgen_lib.runtime.workers import fork_map

__all__ = [
    "VISIBILITY_COLUMNS",
    "GateVerdict",
    "VisibilityCorpus",
    "VisibilitySettings",
    "visibility_check",
    "visibility_gate",
    "visibility_mlp",
    "visibility_probe",
]

#: Columns of ``results/features/visibility.parquet`` (one row per corpus x factor x probe).
VISIBILITY_COLUMNS = (
    "row_id",
    "corpus",
    "factor",
    "probe",
    "score",
    "ci_low",
    "ci_high",
    "majority",
    "n_classes",
    "n",
    "n_test",
)

#: The probes of the check; the gate reads the best of them. ``mlp2`` runs on the gate's
#: factors only (`visibility_check`).
PROBES = ("linear", "nonlinear", "mlp2")


@dataclass(frozen=True)
@schema_fields("features.visibility")
class VisibilitySettings(SchemaSettings):
    """The visibility check (config ``features.visibility``): the nonlinear probe's grid (the
    RBF gamma multiples of the median heuristic and the SVM penalties C it chooses among by CV,
    `fit_kernel_probe`; the regime's V ceiling is the same probe), the fixed-test bootstrap
    resamples, the CV folds of both probes (one draw), and the gate: factor -> the accuracy V
    must reach on a regime corpus for the regime to be read (`visibility_gate`)."""


def visibility_mlp(probes: Mapping[str, Any]) -> MLPGrid:
    """The check's 2-layer probe: the probes stage's (config ``probes.robustness.mlp``: its
    widths, weight decays, folds and solver budget)."""
    return MLPGrid.from_config(probes["robustness"]["mlp"])


def visibility_probe(
    probes: Mapping[str, Any], seed: int, visibility: VisibilitySettings
) -> ProbeSettings:
    """The check's probe: the probes stage's logistic probe (config ``probes``, at `seed`)
    with the check's folds and one draw of them, since the check reads each factor once, on
    every non-test row."""
    return replace(
        ProbeSettings.from_config(probes, "logistic", seed),
        folds=visibility.folds,
        cv_repeats=1,
    )


@dataclass(frozen=True)
class VisibilityCorpus:
    """One corpus of the check: its vision features, its `visible_factors` frame and its
    train (every non-test row) and test rows."""

    name: str
    vision: Mapping[str, np.ndarray]
    factors: pd.DataFrame
    train: Sequence[str]
    test: Sequence[str]


def _split_ids(c: VisibilityCorpus) -> tuple[list[str], list[str]]:
    """A corpus's train and test sample_ids, each with its visible factors; else ValueError
    naming the corpus and the first sample_id without them."""
    train, test = [str(i) for i in c.train], [str(i) for i in c.test]
    if not train or not test:
        raise ValueError(f"visibility_check: corpus {c.name!r} has no train or no test rows")
    missing = [i for i in (*train, *test) if i not in c.factors.index]
    if missing:
        raise ValueError(
            f"visibility_check: corpus {c.name!r}: sample_id {missing[0]!r} has no visible "
            f"factors ({len(missing)} such rows)"
        )
    return train, test


def visibility_check(
    corpora: Sequence[VisibilityCorpus],
    settings: ProbeSettings,
    visibility: VisibilitySettings,
    *,
    mlp: MLPGrid | None = None,
    progress: Callable[[str], Any] | None = None,
    workers: int = 1,
) -> pd.DataFrame:
    """Accuracy of the linear and the nonlinear V probe on each factor of each corpus with
    more than one level among its train rows, and of the 2-layer probe (grid `mlp`, where
    given) on each factor the gate reads (`visibility.gate`), fitted on its train rows and
    scored on its test rows (fixed-test bootstrap CI, `visibility.bootstrap` resamples).

    settings: a logistic `ProbeSettings` (its C grid, folds and CV repeats, and its seed, the
    2-layer probe's too). The (corpus, factor, probe) fits are independent: `workers` forked
    processes compute them (`fork_map`, the same rows for any number of workers), the
    costliest first. A corpus
    whose vectors, factors and split repeat an earlier one's row for row (a null corpus and
    its paired twin show the same frames) is fitted once and given that corpus's rows.
    Returns `VISIBILITY_COLUMNS` rows, ordered by corpus (as given), factor (`FACTORS`) and
    probe.
    """
    if settings.kind != "logistic":
        raise ValueError(f"visibility_check: needs a logistic probe, got {settings.kind!r}")
    say = progress or (lambda _m: None)
    blocks = {}
    jobs = []
    twin_of: dict[str, str] = {}  # corpus -> the earlier corpus whose inputs it repeats
    seen: dict[str, str] = {}
    for c in corpora:
        train, test = _split_ids(c)
        v_tr, v_te = feature_block(c.vision, train), feature_block(c.vision, test)
        shown = [f for f in FACTORS if f in c.factors and _decodable(c.factors[f], train, test)]
        # a corpus whose frames are another's (a null corpus shares its paired twin's): the
        # same vectors, factors and split in row order give the same rows, fitted once
        key = _fingerprint(v_tr, v_te, c.factors.loc[train, shown], c.factors.loc[test, shown])
        if key in seen:
            twin_of[c.name] = seen[key]
            say(f"{c.name}: the vision features, factors and split of {seen[key]}: its rows")
            continue
        seen[key] = c.name
        # the fixed-test resamples of the corpus, shared by its every factor and probe
        idx = resample_indices(len(test), int(visibility.bootstrap), settings.seed)
        blocks[c.name] = (c, train, test, v_tr, v_te, idx)
        jobs += [
            (c.name, f, p)
            for f in shown
            for p in PROBES
            if p != "mlp2" or (mlp is not None and f in visibility.gate)
        ]

    def fit(job: tuple[str, str, str]) -> dict:
        name, factor, probe = job
        c, train, test, v_tr, v_te, idx = blocks[name]
        y_tr = c.factors.loc[train, factor].astype(str).to_numpy(dtype=object)
        y_te = c.factors.loc[test, factor].astype(str).to_numpy(dtype=object)
        if probe == "linear":
            pred = fit_small_probe(v_tr, y_tr, v_te, settings).pred
        elif probe == "nonlinear":
            pred = fit_kernel_probe(
                v_tr, y_tr, v_te, settings, gammas=visibility.gammas, C=visibility.C
            ).pred
        else:
            pred = fit_small_mlp(v_tr, y_tr, v_te, settings, mlp).pred
        pred = np.asarray(pred, dtype=object)
        acc = score("accuracy", y_te, pred)
        lo, hi = score_interval("accuracy", y_te, pred, idx)
        say(f"{name} {factor}, {probe} probe on V: accuracy {acc:.3f} [{lo:.3f}, {hi:.3f}]")
        return {
            "row_id": f"{name}|{factor}|{probe}",
            "corpus": name,
            "factor": factor,
            "probe": probe,
            "score": float(acc),
            "ci_low": float(lo),
            "ci_high": float(hi),
            "majority": float(pd.Series(y_te).value_counts(normalize=True).max()),
            "n_classes": int(len(set(y_tr))),
            "n": len(train),
            "n_test": len(test),
        }

    def cost(job: tuple[str, str, str]) -> float:  # the CVs of the nonlinear probes dominate
        return {"linear": 1.0, "nonlinear": 2.0, "mlp2": 3.0}[job[2]] * len(blocks[job[0]][1])

    rows = fork_map(fit, jobs, workers, cost=cost)
    by_corpus = {c.name: [r for r in rows if r["corpus"] == c.name] for c in corpora}
    out = []
    for c in corpora:
        for r in by_corpus[twin_of.get(c.name, c.name)]:
            out.append({**r, "row_id": f"{c.name}|{r['factor']}|{r['probe']}", "corpus": c.name})
    return pd.DataFrame(out, columns=list(VISIBILITY_COLUMNS))


def _decodable(labels: pd.Series, train: Sequence[str], test: Sequence[str]) -> bool:
    """A factor the check reads: more than one level among the train rows, and no test level
    the train rows lack (a split that holds a level out, as the controlled corpus's held-out
    scale, asks the probe for a class it never saw)."""
    seen = set(labels.loc[train].astype(str))
    return len(seen) > 1 and set(labels.loc[test].astype(str)) <= seen


def _fingerprint(*blocks: np.ndarray | pd.DataFrame) -> str:
    """A digest of the check's inputs of a corpus in row order (vectors' bytes, labels)."""
    import hashlib

    h = hashlib.sha256()
    for b in blocks:
        if isinstance(b, pd.DataFrame):
            h.update(repr(list(b.columns)).encode())
            h.update("\x1f".join(b.astype(str).to_numpy().ravel().tolist()).encode())
        else:
            h.update(np.ascontiguousarray(b).tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class GateVerdict:
    """Whether V passes the visibility gate of one corpus: every factor named by the gate
    decoded at or above its threshold by the better of the two probes."""

    passed: bool
    corpus: str
    scores: dict[str, float]  # factor -> the better probe's accuracy
    thresholds: dict[str, float]

    def sentence(self) -> str:
        """The gate in words, with the decode figures."""
        parts = ", ".join(
            f"{f} {self.scores.get(f, float('nan')):.2f} (gate {t:.2f})"
            for f, t in self.thresholds.items()
        )
        if self.passed:
            return f"V passes the visibility gate on {self.corpus}: {parts}."
        return (
            f"V fails the visibility gate on {self.corpus}: {parts}. A generator that reads V "
            "can pass on only what V holds, so this V cannot show whether generated touch helps."
        )


def visibility_gate(
    rows: pd.DataFrame, corpus: str, thresholds: Mapping[str, float]
) -> GateVerdict:
    """The gate of `corpus` from visibility rows: for each factor of `thresholds`, the
    better (linear or nonlinear) probe's accuracy must reach its threshold. A factor with no
    row (not shown by the corpus) fails the gate."""
    sub = rows[rows["corpus"] == corpus]
    scores = {}
    for factor in thresholds:
        got = sub.loc[sub["factor"] == factor, "score"]
        scores[factor] = float(got.max()) if len(got) else float("nan")
    passed = all(np.isfinite(scores[f]) and scores[f] >= float(t) for f, t in thresholds.items())
    return GateVerdict(bool(passed), corpus, scores, {k: float(v) for k, v in thresholds.items()})
