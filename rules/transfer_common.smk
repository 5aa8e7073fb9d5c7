"""The transfer stage's names (tacgen_lib.plan.transfer); included by transfer.smk."""

from tacgen_lib.plan.transfer import TRANSFER_REPORT

# heads view -> corpus whose heads project the transfer corpus
TRANSFER_VIEWS = PLANS.transfer.views
if TRANSFER_CORPUS:
    TARGETS += [f"{TRANSFER_REPORT}/table.html", f"{TRANSFER_REPORT}/delta.png"]
    EDGES += ["results/transfer/summary.parquet"]
