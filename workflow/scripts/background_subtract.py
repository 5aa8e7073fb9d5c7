"""Background-subtract every tactile frame of a corpus (rule background_subtract)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.io import edges, log
from tacgen_lib.preprocess.frames import sensor_background_map, subtract_backgrounds

logger = log.for_rule(snakemake)
samples = edges.read(snakemake.input.samples, columns=["sensor_id", "tactile"]).frame
sensors = edges.read(snakemake.input.sensors).frame
progress = log.Progress(logger, len(samples), "frames")
proc = subtract_backgrounds(
    samples,
    sensor_background_map(sensors, where=snakemake.input.sensors),
    snakemake.wildcards.variant,
    where=f"rule background_subtract, {snakemake.input.samples}",
    progress=progress.tick,
)
edges.write(snakemake.output[0], proc, producer=snakemake.rule)
logger.info("variant %s: %d frames", snakemake.wildcards.variant, len(proc))
