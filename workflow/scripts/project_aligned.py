"""Aligned projections of every sample of a target corpus by one cell's heads (rule project_aligned)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
import torch

from tacgen_lib.align import checkpoint as align_checkpoint
from tacgen_lib.align import heads as align_heads
from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.io import edges, log
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
feature = AlignSettings.from_config(snakemake.params.settings).feature
target = snakemake.wildcards.target

model = align_checkpoint.load_heads(snakemake.input.heads)
vision = edges.read(snakemake.input.v, columns=[feature], require={feature: "vector"})
tactile = edges.read(snakemake.input.t, columns=[feature], require={feature: "vector"})
ids = sorted(vision.ids)
if set(ids) != set(tactile.ids):
    odd = sorted(set(ids) ^ set(tactile.ids))[0]
    raise edges.EdgeError(
        f"{snakemake.input.v} and {snakemake.input.t}: sample_id {odd!r} is in only one of the "
        "two feature edges; rebuild the features of corpus " + repr(target)
    )
try:
    v_aligned, t_aligned = align_heads.project(
        model,
        vision.subset(ids).vectors[feature],
        tactile.subset(ids).vectors[feature],
        device=torch_device(snakemake.params.device),
    )
except ValueError as exc:
    raise ValueError(
        f"rule project_aligned: heads {snakemake.input.heads} cannot project {feature!r} features "
        f"of corpus {target!r} ({exc}); both corpora need the same feature dimensions"
    ) from exc
frame = pd.DataFrame({"sample_id": ids, "corpus": target})
edges.write(
    snakemake.output[0],
    frame,
    {"v_aligned": v_aligned, "t_aligned": t_aligned},
    producer=snakemake.rule,
)
logger.info("projected %d samples of %s to %d-d", len(ids), target, v_aligned.shape[1])
