"""One simulation or features knob's cost points: each setting's metrics with their CI and
the seconds of its jobs' benchmark files (rule cost_knob_points)."""

import io

import numpy as np
import pandas as pd

from tacgen_lib.cost.benchmarks import read_benchmark
from tacgen_lib.cost.knob_metrics import FRAMES_PER_S, KnobSetting, features_metrics, knob_points
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
knob = snakemake.wildcards.knob
settings, extra = [], {}
for p in snakemake.params.plan:
    table = edges.read(p["metrics"]).frame
    if snakemake.params.stage == "features":
        table = pd.DataFrame(
            features_metrics(
                table, pretraining=p["pretraining"], n_resamples=snakemake.params.bootstrap
            )
        )
    benchmarks = [read_benchmark(b) for b in p["benchmarks"]]
    settings.append(KnobSetting(p["setting"], p["label"], p["is_default"], table, benchmarks))
    if FRAMES_PER_S in snakemake.params.metrics:
        simulate = benchmarks[0]  # the plan lists the simulate job first
        extra[p["label"]] = [
            {
                "metric_id": FRAMES_PER_S,
                "value": snakemake.params.n_sim / simulate.wall,
                "ci_low": np.nan,
                "ci_high": np.nan,
                "uncertainty": "none: one job's wall time (benchmark file)",
            }
        ]
wanted = [m for m in snakemake.params.metrics if m != FRAMES_PER_S]
points = knob_points(knob, snakemake.params.stage, settings, wanted, extra=extra)
# not an edge: the points carry wall times, which never go into a hashed edge
buf = io.BytesIO()
points.to_parquet(buf, index=False)
edges.atomic_write_bytes(snakemake.output[0], buf.getvalue())
for r in points.itertuples(index=False):
    logger.info(
        "%s %s: %s = %.4f [%.4f, %.4f], %.1f s wall, %.1f s CPU over %d jobs",
        knob,
        r.label,
        r.metric,
        r.value,
        r.ci_low,
        r.ci_high,
        r.wall_s,
        r.cpu_s,
        r.n_jobs,
    )
