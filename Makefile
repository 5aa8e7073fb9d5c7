# The two commands of the README are `make run` and `make test`; both set up first.
VENV ?= .venv
BIN := $(VENV)/bin
CORES ?= 2
# which torch build setup installs: cpu, cuda (or a backend such as cu126), auto (cuda where
# an NVIDIA driver is loaded); left empty, the build .venv was last set up with (cpu for a new
# one), so `make setup TORCH=cuda` then a plain `make run` keeps CUDA: tools/torch_build.py
TORCH ?=

.PHONY: setup setup-test run report test test-kernels lint resume estimate

setup:
	@TORCH=$(TORCH) bash tools/setup.sh $(VENV)

## Set up, run the whole DAG on the embedded default config, build the report.
run: setup
	$(BIN)/snakemake --cores $(CORES)
	$(BIN)/snakemake --cores 1 --report results/report.html
	@echo "report: results/report.html"

# recovery is one command
## Continue an interrupted run (kill -9, lost session, OOM): refuses while a Snakemake of this
## directory is alive; else clears the dead run's stale lock and temporary files and reruns
## incomplete jobs. Extra Snakemake arguments through ARGS:
##   make resume ARGS='--configfile config/test.yaml'
resume:
	$(BIN)/python tools/resume.py --cores $(CORES) $(ARGS)

report:
	$(BIN)/snakemake --cores 1 --report results/report.html

## Predict per-rule and total wall time of a config before running it (README, Run-time estimate):
##   make estimate ARGS='--configfile config/paper.yaml --slurm-nodes 8 --cores-per-node 32'
estimate:
	$(BIN)/python -m tacgen_lib.estimate --cores $(CORES) $(ARGS)

lint:
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/snakefmt --check Snakefile rules/
	$(BIN)/snakemake --lint --configfile config/test.yaml

## Set up, lint, run every test (unit, property, hard cases, workflow runs on config/test.yaml,
## and the real one-node SLURM fan-out, which skips itself, saying why, where it cannot run),
## on $(CORES) pytest-xdist workers (a module stays on one worker; the longest workflow modules go first).
## Beside them, the tests that are not workflow runs again under other CPU kernels
## (test-kernels: its output follows the main run's), at the lowest CPU priority: the
## workflow runs leave a core idle at times (a DAG's narrow stages, SLURM's polling), and the
## variant fills those gaps instead of slowing the runs down. Fails if either fails.
## TACGEN_SLURM_TEST=0 leaves the SLURM test out (it installs slurm-wlm + munge as root).
setup-test:
	@TORCH=$(TORCH) bash tools/setup.sh $(VENV) --browser

test: setup-test lint
	@kernels_log=$$(mktemp); \
	nice -n 19 $(BIN)/python tools/kernel_variants.py >"$$kernels_log" 2>&1 & kernels=$$!; \
	TACGEN_SLURM_TEST=$${TACGEN_SLURM_TEST:-1} $(BIN)/python -m pytest -ra --durations=25 -n $(CORES) --dist loadfile --no-loadscope-reorder; \
	main=$$?; wait $$kernels; kernels_rc=$$?; \
	echo "---- the same tests under other CPU kernels (tools/kernel_variants.py) ----"; \
	cat "$$kernels_log"; rm -f "$$kernels_log"; \
	test $$main -eq 0 && test $$kernels_rc -eq 0

## The tests that are not workflow runs again under other CPU kernels (OpenBLAS core type, MKL
## and torch instruction sets, numpy's AVX-512 dispatch, 2 threads): a float comparison that
## holds on this CPU's kernels only fails here, not on a user's CPU. One variant:
##   make test-kernels ARGS='--variant generic'    (every variant: ARGS=--all)
test-kernels: setup
	$(BIN)/python tools/kernel_variants.py $(ARGS)
