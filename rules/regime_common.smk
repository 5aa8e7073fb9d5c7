"""Helpers of the regime (where generated touch helps); included by regime.smk."""

from tacgen_lib.corpus.splits import split_size
from tacgen_lib.generate.regime_sets import PAIRINGS, check_regime_sizes, regime_corpora

# a config without the section (one given with --replace-workflow-config) runs no regime
REGIME = config.get("regime") or {
    "rhos": [],
    "targets": {},
    "n_labelled": [2],
    "n_pool": [2],
    "seeds": [0],
}
# its natural corpora, one per rho (joined to the corpora by common.smk)
REGIME_CORPORA = list(regime_corpora(REGIME))
REGIME_DIR = "results/generate/regime"
REGIME_CELL = f"{REGIME_DIR}/{{corpus}}/seed~{{seed}}"
REGIME_REPORT = "results/report/regime"
REGIME_ITEMS = {
    "findings": "html",
    "table": "html",
    "ladder": "html",
    "heatmap": "png",
    "curves": "png",
}
# every (pool size, pairing) generator of a corpus x seed, in the order of its outputs
REGIME_CELLS = [(int(n), p) for n in REGIME["n_pool"] for p in PAIRINGS]


for _c in REGIME_CORPORA:
    if _c in config["splits"].get("by_scale", {}):
        raise ValueError(
            f"config splits.by_scale: corpus {_c!r} is the regime's; it needs the random split"
        )
    check_regime_sizes(
        _c,
        int(CORPORA[_c]["n"]),
        # the corpus's test split as make_splits draws it
        split_size(
            int(CORPORA[_c]["n"]), config["splits"]["fractions"].get("test", 0.0)
        ),
        REGIME["n_labelled"],
        REGIME["n_pool"],
    )


def regime_cells():
    return [(c, str(s)) for c in REGIME_CORPORA for s in REGIME["seeds"]]


def regime_files(path):
    return [path.format(corpus=c, seed=s) for c, s in regime_cells()]


def regime_t_gen(corpus, seed):
    return [
        f"{REGIME_CELL}/pool~{n}/{p}/t_gen.parquet".format(corpus=corpus, seed=seed)
        for n, p in REGIME_CELLS
    ]
