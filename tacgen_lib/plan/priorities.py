"""Job priorities the rules give (Snakemake starts ready jobs of higher priority first and does
not look at what waits for a job)."""

from __future__ import annotations

#: The policy stage is the DAG's last long chain (features -> alignment heads -> palpate ->
#: train -> roll out -> aggregate): its rules go first, or the chain starts after the probes and
#: leaves a core idle at the end of a run.
CHAIN_PRIORITY = 1
#: The vision backbone's pretraining, a long one-thread job that every job reading V waits for,
#: goes before everything else that is ready: started late, it ran alone at the end of the
#: corpus stage with a core idle. The latent generators' training (long one-thread jobs) goes
#: with the chain: started last, one ran alone with a core idle while the regime's two-thread
#: jobs waited for both cores.
FIRST_PRIORITY = 2
