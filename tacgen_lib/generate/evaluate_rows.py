"""The rows of one generator's two evaluation edges (`evaluate.evaluate_generator`): a summary
row per target x cell x input (`summary_row`, its id `summary_row_id`), and the pairing
permutation draws of each cell and target (`permutation_rows`, as a frame with its dtypes even
when empty: `permutation_frame`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from tacgen_lib.generate.fidelity import PERMUTATION_COLUMNS

#: The dtypes of the permutation-draw table (`permutation_frame` of no rows keeps them).
PERMUTATION_DTYPES = {
    "row_id": "str",
    "corpus": "str",
    "target": "str",
    "sampler": "str",
    "seed": "int64",
    "steps": "int64",
    "permutation": "int64",
    "guidance": "float64",
    "statistic": "float64",
    "observed": "float64",
}


def summary_row(
    base: dict, inp: str, boot: dict, vs_nl: dict | None, vs_ridge: dict | None = None
) -> dict:
    """One summary row: `base`'s columns, the input added to V, its paired bootstrap against V
    (`boot`), against the nonlinear V baseline (`vs_nl`) and against the ridge V->T generator's
    mean (`vs_ridge`), NaN where a comparison is not made."""
    return {
        **base,
        "input": inp,
        "score": boot["vt_score"],
        "v_score": boot["v_score"],
        "delta": boot["delta"],
        "ci_low": boot["ci_low"],
        "ci_high": boot["ci_high"],
        "p_gt0": boot["p_gt0"],
        "delta_vs_nonlinear": np.nan if vs_nl is None else vs_nl["delta"],
        "ci_low_vs_nonlinear": np.nan if vs_nl is None else vs_nl["ci_low"],
        "ci_high_vs_nonlinear": np.nan if vs_nl is None else vs_nl["ci_high"],
        "delta_vs_ridge": np.nan if vs_ridge is None else vs_ridge["delta"],
        "ci_low_vs_ridge": np.nan if vs_ridge is None else vs_ridge["ci_low"],
        "ci_high_vs_ridge": np.nan if vs_ridge is None else vs_ridge["ci_high"],
        # the family-wise interval of a generated-touch row (`evaluate_probes.family_interval`); NaN
        "ci_low_fw": boot.get("ci_low_fw", np.nan),
        "ci_high_fw": boot.get("ci_high_fw", np.nan),
        "ci_low_fw_vs_ridge": np.nan if vs_ridge is None else vs_ridge.get("ci_low_fw", np.nan),
        "ci_high_fw_vs_ridge": np.nan if vs_ridge is None else vs_ridge.get("ci_high_fw", np.nan),
    }


def summary_row_id(
    corpus: str, target: str, seed: int, cell: tuple[str, str, str], inp: str
) -> str:
    """The id of a summary row: corpus, target, seed, cell (sampler, guidance, steps), input."""
    sampler, guidance, steps = cell
    return f"{corpus}|{target}|seed~{seed}|{sampler}|w={guidance}|steps={steps}|{inp}"


def permutation_rows(
    corpus: str,
    seed: int,
    target: str,
    cell: tuple[str, str, str],
    null: Sequence[float],
    observed: float,
) -> list[dict]:
    """The pairing permutation draws (`null`) of one cell and target beside the observed
    matched cosine: one row each, columns `fidelity.PERMUTATION_COLUMNS`."""
    sampler, guidance, steps = cell
    label = f"{sampler}|w={guidance}|steps={steps}"
    return [
        {
            "row_id": f"{corpus}|seed~{seed}|{label}|{target}|perm~{k}",
            "corpus": corpus,
            "seed": int(seed),
            "target": target,
            "sampler": sampler,
            "guidance": float(guidance),
            "steps": int(steps),
            "permutation": k,
            "statistic": float(s),
            "observed": observed,
        }
        for k, s in enumerate(null)
    ]


def permutation_frame(rows: list[dict]) -> pd.DataFrame:
    """The permutation-draw table of `rows`; with no rows, its columns still carry their
    dtypes (`PERMUTATION_DTYPES`)."""
    frame = pd.DataFrame(rows, columns=list(PERMUTATION_COLUMNS))
    if frame.empty:
        frame = frame.astype(PERMUTATION_DTYPES)
    return frame
