"""Cost of accuracy: job run times from Snakemake benchmark files, knob sweeps, and run-time
estimates for a config before it runs."""
