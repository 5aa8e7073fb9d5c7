"""Input and output of the DAG: Parquet edges and their sidecars, PNG images, rule logs, config validation."""
