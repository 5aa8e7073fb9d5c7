"""Example grid of one corpus for the report (rule corpus_examples)."""

from tacgen_lib.io import edges, log
from tacgen_lib.report.figures import corpus_example_grid, label_distribution_figure
from tacgen_lib.report.write import write_figure

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
logger.info("example grid of %d samples", snakemake.params.n)
