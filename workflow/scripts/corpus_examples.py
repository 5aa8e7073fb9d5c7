"""Example grid of one corpus for the report (rule corpus_examples)."""

from tacgen_lib import edges, log
from tacgen_lib.report_figures import corpus_example_grid

logger = log.for_rule(snakemake)
samples = edges.read(snakemake.input.samples)
sensors = edges.read(snakemake.input.sensors)
splits = edges.read(snakemake.input.splits).frame
fig = corpus_example_grid(
    samples.frame, sensors.frame, splits, n=snakemake.params.n, title=snakemake.wildcards.corpus
)
fig.savefig(snakemake.output[0], dpi=110, metadata={"Software": None})
logger.info("example grid of %d samples", snakemake.params.n)
