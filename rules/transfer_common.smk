"""Helpers of the transfer stage (its views and their aligned edges); included by transfer.smk."""

TRANSFER_REPORT = "results/report/transfer"
TRANSFER_VIEWS = {}  # heads view -> corpus whose heads project the transfer corpus
if TRANSFER_CORPUS:
    _where = f"config transfer.corpus = {TRANSFER_CORPUS!r}"
    if TRANSFER_CORPUS not in CORPORA:
        raise ValueError(f"{_where}: not a corpus (have {sorted(CORPORA)})")
    if TRANSFER_CORPUS not in (config["splits"].get("by_object") or {}):
        raise ValueError(
            f"{_where}: the corpus must be split by object (config splits.by_object), so no "
            "object is both fitted and tested"
        )
    for _key in ("source", "floor"):
        if TRANSFER[_key] not in ALIGN_CORPORA:
            raise ValueError(
                f"config transfer.{_key} = {TRANSFER[_key]!r} is not in align.corpora "
                f"{ALIGN_CORPORA}: its heads are not trained"
            )
    TRANSFER_VIEWS = {
        "source": TRANSFER["source"],
        "target": TRANSFER_CORPUS,
        "floor": TRANSFER["floor"],
    }
    TARGETS += [f"{TRANSFER_REPORT}/table.html", f"{TRANSFER_REPORT}/delta.png"]
    EDGES += ["results/transfer/summary.parquet"]


def transfer_aligned(view, seed):
    """The transfer corpus's aligned projections by one view's heads (the probes' heads
    cell, alignment seed `seed`; the transfer corpus's own heads on all of its train rows).
    """
    heads = config["probes"]["heads"]
    heads_from = TRANSFER_VIEWS[view]
    n_train = "all" if heads_from == TRANSFER_CORPUS else heads["n_train"]
    return aligned_edge(
        heads_from,
        TRANSFER_CORPUS,
        heads["variant"],
        seed,
        heads["tau"],
        n_train,
    )
