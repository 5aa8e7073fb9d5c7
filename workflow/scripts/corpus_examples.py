"""Example grid of one corpus for the report (rule corpus_examples)."""

from tacgen_lib import edges, log
from tacgen_lib.report_figures import corpus_example_grid, label_distribution_figure

logger = log.for_rule(snakemake)
samples = edges.read(snakemake.input.samples)
sensors = edges.read(snakemake.input.sensors)
splits = edges.read(snakemake.input.splits).frame
fig = corpus_example_grid(
    samples.frame, sensors.frame, splits, n=snakemake.params.n, title=snakemake.wildcards.corpus
)
fig.savefig(snakemake.output.examples, dpi=110, metadata={"Software": None})
labels = label_distribution_figure(
    samples.frame.drop(columns=["rgb", "tactile"]), title=snakemake.wildcards.corpus
)
labels.savefig(snakemake.output.labels, dpi=110, metadata={"Software": None})
logger.info("example grid of %d samples", snakemake.params.n)
