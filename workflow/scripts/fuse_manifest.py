"""Fuse every corpus's metadata into one manifest keyed by sample_id (rule fuse_manifest)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pyarrow.parquet as pq

from tacgen_lib.corpus.manifest import fuse_manifest
from tacgen_lib.io import edges, hashed, log

logger = log.for_rule(snakemake)
frames = []
for path in snakemake.input.samples:
    hashed.verify(path)
    names = pq.read_schema(path).names
    frames.append(edges.read(path, columns=[c for c in names if c not in ("rgb", "tactile")]).frame)
manifest = fuse_manifest(frames, sources=[str(p) for p in snakemake.input.samples])
edges.write(snakemake.output[0], manifest, producer=snakemake.rule)
logger.info("manifest: %d samples from %d corpora", len(manifest), manifest["corpus"].nunique())
