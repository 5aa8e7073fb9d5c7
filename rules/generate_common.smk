"""Helpers of the generate stage (grid expansion, canonical cell paths); included by generate.smk."""

from tacgen_lib.generate.sampling_cells import (
    BASELINES,
    GENERATOR,
    SAMPLE_CELL,
    SAMPLE_CONSTRAINTS,
    family_size,
    generator_cells,
    guidance_text,
    sample_cells,
)
from tacgen_lib.generate.settings import check_grid, generate_grids

GENERATE = config["generate"]
# the C and lambda grids of every probe that judges generated touch (generate.C, .lambdas)
GENERATE_GRIDS = generate_grids(GENERATE)
# config order: the first corpus feeds the PCA figure
GENERATE_CORPORA = list(GENERATE["corpora"])
GENERATE_REPORT = "results/report/generate"
GENERATE_CELLS = sample_cells(GENERATE["guidance"], GENERATE["samplers"])
# the probes no generator changes (fit_generator_baselines) serve the latent generator's
# corpora and the pixel generators' judged ones: per corpus, the targets of both
BASELINE_TARGETS = {c: dict(t) for c, t in GENERATE["corpora"].items()}
for _c, _t in ((config.get("pixel") or {}).get("corpora") or {}).items():
    BASELINE_TARGETS[_c] = {**BASELINE_TARGETS.get(_c, {}), **_t}
BASELINE_CORPORA = list(BASELINE_TARGETS)
GENERATE_ITEMS = {
    "headline": "html",
    "honesty": "html",
    "family": "html",
    "protocol": "html",
    "fidelity": "html",
    "heatmap": "png",
    "steps": "png",
    "pca": "png",
    "permutation": "png",
    "curves": "png",
}
check_grid(GENERATE["samplers"], GENERATE["train_steps"])
for _c in GENERATE_CORPORA:
    if _c not in CORPORA:
        raise ValueError(
            f"config generate.corpora: {_c!r} is not a corpus (have {sorted(CORPORA)})"
        )


def generate_ref():
    """The report's reference cell: first sampler, its most steps, w = 1 if in the grid."""
    sampler = next(iter(GENERATE["samplers"]))
    ws = [guidance_text(w) for w in GENERATE["guidance"]]
    return {
        "sampler": sampler,
        "steps": max(int(s) for s in GENERATE["samplers"][sampler]),
        "guidance": "1" if "1" in ws else ws[0],
    }


def generate_ref_cell():
    """The reference cell as (sampler, guidance text, steps text), a member of GENERATE_CELLS."""
    ref = generate_ref()
    return (ref["sampler"], ref["guidance"], str(ref["steps"]))


def generators():
    return [(c, str(s)) for c in GENERATE_CORPORA for s in GENERATE["seeds"]]


def generator_files(path):
    return [path.format(corpus=c, seed=s) for c, s in generators()]


def all_sample_cells():
    return [(c, s, *cell) for c, s in generators() for cell in GENERATE_CELLS]


def sample_edge(corpus, seed, sampler, guidance, steps):
    return f"{SAMPLE_CELL}/t_gen.parquet".format(
        corpus=corpus, seed=seed, sampler=sampler, guidance=guidance, steps=steps
    )


#: One sampling cell's seconds, timed by its generator's sampling job (benchmark format)
SAMPLE_SECONDS = "results/benchmarks/sample_generator/{corpus}/{seed}_{sampler}_{guidance}_{steps}.tsv"


def sample_benchmark(corpus, seed, sampler, guidance, steps):
    return SAMPLE_SECONDS.format(
        corpus=corpus, seed=seed, sampler=sampler, guidance=guidance, steps=steps
    )


def generate_tactile(corpus):
    return feature_edge(corpus, "tactile", GENERATE["variant"])
