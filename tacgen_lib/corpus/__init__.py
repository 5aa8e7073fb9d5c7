"""The corpus stage: simulated (`sim`) and real (`ingest`) corpora, the fused manifest, fixed splits."""
