"""The vision features of a natural corpus between its rho grid's ends, shared from the ends
(rule share_natural_vision): each of its samples looks as at rho = 0 or as at rho = 1
(`tacgen_lib.corpus.sim.samples._natural_spec`), so each RGB frame is byte-identical to one of
theirs (checked here, sample by sample) and so are its features."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from tacgen_lib.corpus.shared_touch import frame_twins, shared_vectors
from tacgen_lib.io import edges, log

logger = log.for_rule(snakemake)
inp = snakemake.input
target = edges.read(inp.target, columns=["rgb"]).frame
twins = frame_twins(
    target,
    [edges.read(p, columns=["rgb"]).frame for p in inp.sources],
    where=f"rule {snakemake.rule} ({inp.target})",
)
features = [edges.read(p) for p in inp.features]
ids = target["sample_id"].astype(str).tolist()
vectors = shared_vectors(ids, twins, [(f.ids, f.vectors) for f in features])
edges.write(snakemake.output[0], target[["sample_id"]], vectors, producer=snakemake.rule)
counts = [sum(k == j for k, _ in twins.values()) for j in range(len(inp.sources))]
logger.info(
    "%d samples: frames identical to %s; their features shared (%s)",
    len(ids),
    ", ".join(f"{p} ({c})" for p, c in zip(inp.sources, counts, strict=True)),
    ", ".join(f"{k}[{v.shape[1]}]" for k, v in vectors.items()),
)
