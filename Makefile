# The two commands of the README are `make run` and `make test`; both set up first.
VENV ?= .venv
BIN := $(VENV)/bin
CORES ?= 2

.PHONY: setup run report test lint resume estimate

setup:
	@bash tools/setup.sh $(VENV)

## Set up, run the whole DAG on the embedded default config, build the report.
run: setup
	$(BIN)/snakemake --cores $(CORES)
	$(BIN)/snakemake --cores 1 --report results/report.html
	@echo "report: results/report.html"

# ---- issue 15: recovery is one command ---- begin
## Continue an interrupted run (kill -9, lost session, OOM): refuses while a Snakemake of this
## directory is alive; else clears the dead run's stale lock and temporary files and reruns
## incomplete jobs. Extra Snakemake arguments through ARGS:
##   make resume ARGS='--configfile config/test.yaml'
resume:
	$(BIN)/python tools/resume.py --cores $(CORES) $(ARGS)
# ---- issue 15 ---- end

report:
	$(BIN)/snakemake --cores 1 --report results/report.html

## Predict per-rule and total wall time of a config before running it (README, Run-time estimate):
##   make estimate ARGS='--configfile config/paper.yaml --slurm-nodes 8 --cores-per-node 32'
estimate:
	$(BIN)/python -m tacgen_lib.cost.estimate --cores $(CORES) $(ARGS)

lint:
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/snakefmt --check Snakefile rules/
	$(BIN)/snakemake --lint --configfile config/test.yaml

## Set up, lint, run every test (unit, property, hard cases, workflow runs on config/test.yaml,
## and the real one-node SLURM fan-out, which skips itself, saying why, where it cannot run).
## TACGEN_SLURM_TEST=0 leaves the SLURM test out (it installs slurm-wlm + munge as root).
test: setup lint
	TACGEN_SLURM_TEST=$${TACGEN_SLURM_TEST:-1} $(BIN)/python -m pytest -ra
