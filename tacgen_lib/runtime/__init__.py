"""The job runtime: the preloaded interpreter local script jobs fork from (`preload`), the local
scheduler's rate-limit patch (`scheduler`), where a torch job computes (`device`), a job's
cells on forked workers (`workers`), and what a job measured (`benchmarks`: Snakemake
benchmark files). Predicting a config's run time before it runs is `tacgen_lib.estimate`."""
