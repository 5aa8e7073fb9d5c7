"""The generate stage's names (tacgen_lib.plan.generate); included by generate.smk."""

from tacgen_lib.generate.sampling_cells import (
    BASELINES,
    GENERATOR,
    SAMPLE_CELL,
    SAMPLE_CONSTRAINTS,
    family_size,
    generator_cells,
)
from tacgen_lib.plan.generate import (
    GENERATE_ITEMS,
    GENERATE_REPORT,
    SAMPLE_SECONDS,
    sample_benchmark,
    sample_edge,
)

GENERATE = config["generate"]
# the C and lambda grids of every probe that judges generated touch (generate.C, .lambdas)
GENERATE_GRIDS = PLANS.generate.grids
# config order: the first corpus feeds the PCA figure
GENERATE_CORPORA = PLANS.generate.corpora
GENERATE_CELLS = PLANS.generate.cells
# the probes no generator changes (fit_generator_baselines) serve the latent generator's
# corpora and the pixel generators' judged ones: per corpus, the targets of both
BASELINE_TARGETS = PLANS.generate.baseline_targets
BASELINE_CORPORA = list(BASELINE_TARGETS)
