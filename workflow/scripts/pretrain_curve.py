"""The pretraining curve (DINO, MAE or SimCLR) of one modality's backbone as a report figure (rule
pretrain_curve). Apart from pretrain_backbone, so an edit to the report's code reruns this
figure, not the backbone and everything downstream of it."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.io import edges, log
from tacgen_lib.report.figures import pretrain_curve_figure
from tacgen_lib.report.write import write_figure

OBJECTIVE_NAMES = {"dino": "DINO", "mae": "MAE", "simclr": "SimCLR", "random": "no"}
logger = log.for_rule(snakemake)
curve = edges.read(snakemake.input.curve).frame
fig = pretrain_curve_figure(
    curve,
    title=f"{snakemake.wildcards.modality} backbone ({snakemake.params.arch})",
    loss=f"{OBJECTIVE_NAMES[snakemake.params.objective]} loss",
    empty_note="loaded from an official checkpoint: no pretraining curve",
)
write_figure(fig, snakemake.output.figure)
logger.info("%d epochs drawn", len(curve))
