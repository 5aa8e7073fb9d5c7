"""Run times: reading Snakemake benchmark files, and predicting a config's run time before it
runs (`estimate`: the DAG's jobs, `units` of work per rule, a `calibration` fitted on benchmark
files, a `schedule` over cores or a SLURM cluster)."""
