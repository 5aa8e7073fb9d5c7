"""Synthetic worlds shared by the generator tests: V sees a visible attribute, touch a hidden
one that V cannot, and the labels need both."""

from __future__ import annotations

import numpy as np
import pandas as pd

from tacgen_lib.generate.baselines import TargetSpec
from tacgen_lib.probes.rows import family_rows
from tacgen_lib.probes.settings import ProbeSettings


def small_probes(
    kind: str, lambdas: list, C: list, *, controls: int = 0, bootstrap: int = 200, seed: int = 0
) -> ProbeSettings:
    """Probe settings of the generator tests: a small λ / C grid, 3 folds, `bootstrap`
    fixed-test resamples and `controls` draws of every control (0: none)."""
    draws = ("train_resamples", "permutations", "label_permutations", "random_draws")
    cfg = {"lambdas": lambdas, "C": C, "folds": 3, "bootstrap": bootstrap}
    return ProbeSettings.from_config(cfg | dict.fromkeys(draws, controls), kind, seed)


def toy_world(n=240, seed=0):
    """V sees a visible attribute; touch sees a hidden one that V cannot; labels need both."""
    rng = np.random.default_rng(seed)
    visible = rng.normal(size=n)
    hidden = rng.normal(size=n)
    ids = [f"s{i:04d}" for i in range(n)]
    v = np.column_stack([visible, rng.normal(size=(n, 3))]).astype(np.float32)
    t = np.column_stack(
        [hidden, visible + 0.1 * rng.normal(size=n), rng.normal(size=(n, 2))]
    ).astype(np.float32)
    manifest = pd.DataFrame(
        {"sample_id": ids, "corpus": "toy", "force_p50": visible + 2.0 * hidden}
    )
    split = np.where(np.arange(n) % 5 == 0, "test", np.where(np.arange(n) % 5 == 1, "val", "train"))
    splits = pd.DataFrame({"sample_id": ids, "corpus": "toy", "split": split})
    return ids, v, t, manifest, splits


def train_ids(splits: pd.DataFrame) -> list[str]:
    """The toy world's generator train rows."""
    return splits.loc[splits["split"] == "train", "sample_id"].tolist()


def toy_specs():
    """A ridge and a logistic target on the toy world, with small probe grids."""
    ids, v, t, manifest, splits = toy_world()
    manifest["hardness"] = np.where(manifest["force_p50"] > 0, "hard", "soft")
    specs = [
        TargetSpec(
            name,
            family_rows(manifest, splits, corpus="toy", target=name, kind=kind),
            small_probes(kind, [0.1, 1, 10], [0.1, 10]),
        )
        for name, kind in (("force_p50", "ridge"), ("hardness", "logistic"))
    ]
    return ids, dict(zip(ids, v, strict=True)), dict(zip(ids, t, strict=True)), specs


def evaluate_one(spec: TargetSpec, vision: dict, t_real: dict, t_gen: dict, **kw):
    """`evaluate_generator` of one target on corpus "toy" against its baselines (fitted at
    gamma 1); `kw`: the rest of its arguments (seed, permutations, generator_train_ids...)."""
    from tacgen_lib.generate.baselines import fit_baselines
    from tacgen_lib.generate.evaluate import evaluate_generator

    baselines = {spec.name: fit_baselines(spec, vision, t_real, gammas=(1.0,))}
    data = {"vision": vision, "t_real": t_real, "t_gen": t_gen, "baselines": baselines}
    return evaluate_generator([spec], corpus="toy", **data, **kw)
