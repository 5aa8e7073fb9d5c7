"""The align stage's names (tacgen_lib.plan.align); included by align.smk.

`PLANS.align.aligned_edge(...)` is what other stages (probes) use to ask for aligned
projections.
"""

from tacgen_lib.align.cell_names import (
    CELL_CONSTRAINTS,
    CELL_PATTERN,
    cell_name,
    tau_text,
)
from tacgen_lib.plan.align import ALIGN_CELL, ALIGN_REPORT

ALIGN = config["align"]
ALIGN_CORPORA = PLANS.align.corpora
HEADS_CORPORA = PLANS.align.heads_corpora
