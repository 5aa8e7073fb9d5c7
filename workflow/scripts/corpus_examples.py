"""Example grid, label distributions and force bands of one corpus for the report (rule
corpus_examples)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.corpus.force_bands import corpus_force_bands
from tacgen_lib.io import edges, log
from tacgen_lib.report.corpus import force_band_table
from tacgen_lib.report.figures import corpus_example_grid, label_distribution_figure
from tacgen_lib.report.write import write_figure, write_table

logger = log.for_rule(snakemake)
samples = edges.read(snakemake.input.samples)
sensors = edges.read(snakemake.input.sensors)
splits = edges.read(snakemake.input.splits).frame
fig = corpus_example_grid(
    samples.frame, sensors.frame, splits, n=snakemake.params.n, title=snakemake.wildcards.corpus
)
write_figure(fig, snakemake.output.examples)
labels = label_distribution_figure(
    samples.frame.drop(columns=["rgb", "tactile"]), title=snakemake.wildcards.corpus
)
write_figure(labels, snakemake.output.labels)
corpus = snakemake.wildcards.corpus
check = corpus_force_bands(samples.frame, seed=0)  # None: a real corpus, no true force
write_table(
    force_band_table(corpus, check),
    snakemake.output.force_bands,
    title=f"{corpus}: force bands against the true contact force",
    mono=(),
)
logger.info(
    "example grid of %d samples; force bands: %s",
    snakemake.params.n,
    "no true force recorded"
    if check is None
    else f"R2 {check.r2:.3f}, coverage {check.coverage:.3f} (control {check.shuffled_coverage:.3f})",
)
