"""What one simulation setting buys: force band width, force and hardness probes (rule
cost_sim_probe)."""

import pandas as pd
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.cost.knob_metrics import BAND_WIDTH, METRIC_COLUMNS, force_band_width
from tacgen_lib.cost.knob_probes import probe_metrics
from tacgen_lib.io import edges, log
from tacgen_lib.probes.protocol import ProbeSettings, family_rows

logger = log.for_rule(snakemake)
probes_cfg = snakemake.params.probes
seed = int(probes_cfg["seeds"][0])
labels = ["sample_id", "corpus", "force_p05", "force_p50", "force_p95", "hardness"]
samples = edges.read(snakemake.input.samples, columns=labels[1:]).frame
splits = edges.read(snakemake.input.splits).frame
vision = edges.read(snakemake.input.vision, require={"vit": "vector"})
tactile = edges.read(snakemake.input.tactile, require={"vit": "vector"})
width, lo, hi = force_band_width(
    samples["force_p05"].to_numpy(),
    samples["force_p95"].to_numpy(),
    n_resamples=int(probes_cfg["bootstrap"]),
    seed=seed,
)
rows = [
    {
        "metric_id": BAND_WIDTH,
        "value": width,
        "ci_low": lo,
        "ci_high": hi,
        "uncertainty": f"95 % bootstrap CI over the {len(samples)} samples",
    }
]
logger.info("force band p05-p95: %.4f N [%.4f, %.4f] over %d samples", width, lo, hi, len(samples))
for target, kind in (("force_p50", "ridge"), ("hardness", "logistic")):
    family = family_rows(samples, splits, corpus=snakemake.params.corpus, target=target, kind=kind)
    # the probes train on train + val rows; test rows only score them (as rule probe)
    assert_trainable(family.train_ids, splits, rule=snakemake.rule, allowed=("train", "val"))
    with threadpool_limits(snakemake.threads):
        found = probe_metrics(
            family,
            family.train_test(vision, "vit"),
            family.train_test(tactile, "vit"),
            ProbeSettings.from_config(probes_cfg, kind, seed),
        )
    for r in found:
        logger.info(
            "%s: %.4f [%.4f, %.4f] (%d train/val, %d test rows)",
            r["metric_id"],
            r["value"],
            r["ci_low"],
            r["ci_high"],
            family.n_train,
            family.n_test,
        )
    rows += found
edges.write(
    snakemake.output[0],
    pd.DataFrame(rows, columns=METRIC_COLUMNS),
    key="metric_id",
    producer=snakemake.rule,
)
