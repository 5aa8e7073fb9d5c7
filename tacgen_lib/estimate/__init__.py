"""The run-time estimate: a config's per-rule and total wall time before it runs. The DAG's jobs
(`dag`), the `units` of work of each rule's jobs (their counts in `counts`, their arithmetic in
`flops`), per-unit costs fitted on benchmark files (`calibration`), a `schedule` over cores or a
SLURM cluster, the prediction (`predict`), its command (`command`; `python -m
tacgen_lib.estimate`) and each SLURM job's time limit from it (`resources`)."""
