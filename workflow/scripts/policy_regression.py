"""Ridge probes V vs V+T-aligned -> required grip force, per alignment seed (rule policy_regression)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import numpy as np
import pandas as pd

from tacgen_lib.io import edges, log
from tacgen_lib.policy import data
from tacgen_lib.policy.evaluate import grip_force_regression
from tacgen_lib.policy.settings import PolicySettings

logger = log.for_rule(snakemake)
settings = PolicySettings.from_config(snakemake.params.settings)
edge = edges.read(snakemake.input.palpation)
frame, vec = edge.frame, edge.vectors
train = (frame["split"] == "train").to_numpy()
data.training_rows(frame, frame["episode_id"][train], rule=snakemake.rule)
y = np.log(frame["window_lo"].to_numpy())  # the least force that holds the object (log N)
rows = []
for seed in snakemake.params.align_seeds:
    t = vec[f"t_aligned~{seed}"]
    res = grip_force_regression(
        vec["v"], np.hstack([vec["v"], t]), y, train, settings.bootstrap, settings.seed
    )
    rows.append({"row_id": f"align_seed~{seed}", "align_seed": int(seed), **res})
    logger.info(
        "align seed %s: R2 V %.3f, V+T %.3f, dR2 %+.3f",
        seed,
        res["r2_v"],
        res["r2_vt"],
        res["delta_r2"],
    )
edges.write(snakemake.output[0], pd.DataFrame(rows), key="row_id", producer=snakemake.rule)
