"""The tactile features of a natural corpus of the regime's rho grid, shared from the grid's
first corpus (rule share_natural_touch): the grid is simulated together and presses each sample
once (rule simulate_natural_grid), so the two corpora's tactile frames are byte-identical
(checked here, sample by sample) and so are their background-subtracted frames and features;
only the sample_ids differ."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd

from tacgen_lib.corpus.shared_touch import touch_twins
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
inp = snakemake.input
twins = touch_twins(
    edges.read(inp.source, columns=["tactile"]).frame,
    edges.read(inp.target, columns=["tactile"]).frame,
    where=f"rule {snakemake.rule} ({inp.source} -> {inp.target})",
)
features = edges.read(inp.features)
edges.write(
    snakemake.output[0],
    pd.DataFrame({"sample_id": [twins[str(i)] for i in features.ids]}),
    features.vectors,
    producer=snakemake.rule,
)
logger.info(
    "%d samples: tactile frames identical to %s; its features shared (%s)",
    len(twins),
    inp.source,
    ", ".join(f"{k}[{v.shape[1]}]" for k, v in features.vectors.items()),
)
