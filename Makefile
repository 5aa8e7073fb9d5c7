# The two commands of the README are `make run` and `make test`; both set up first.
VENV ?= .venv
BIN := $(VENV)/bin
CORES ?= 2

.PHONY: setup run report test lint

setup:
	@bash tools/setup.sh $(VENV)

## Set up, run the whole DAG on the embedded default config, build the report.
run: setup
	$(BIN)/snakemake --cores $(CORES)
	$(BIN)/snakemake --cores 1 --report results/report.html
	@echo "report: results/report.html"

report:
	$(BIN)/snakemake --cores 1 --report results/report.html

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
