"""The regime's names (tacgen_lib.plan.regime); included by regime.smk."""

from tacgen_lib.plan.regime import (
    REGIME_CELL,
    REGIME_CONTROL,
    REGIME_DIR,
    REGIME_ITEMS,
    REGIME_REPORT,
)

REGIME = PLANS.regime.settings
# its natural corpora, one per rho (joined to the corpora by validate_config)
REGIME_CORPORA = PLANS.regime.corpora
# every (pool size, pairing) generator of a corpus x seed, in the order of its outputs
REGIME_CELLS = PLANS.regime.generator_cells
# the corpus of the curve's positive control (none without a curve or a control SNR)
REGIME_CONTROL_CORPORA = PLANS.regime.control_corpora
