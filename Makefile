# Two commands on a fresh clone:  `make run` (the seed paper experiment)  and  `make test`.
# Both run scripts/setup.sh first, which installs whatever is missing (venv, torch, Vulkan).
PY := .venv/bin/python
ARGS ?=

.PHONY: setup run test test-slow test-all bench gpu-check docs
setup:
	@bash scripts/setup.sh

run: setup
	$(PY) -m realize experiment=seed_paper $(ARGS)

# test files run in parallel, one file per process (its module fixtures built once), one process
# per core up to 4, the longest files first (tests/file_seconds.py). TEST_JOBS=0 runs them in
# this process. make test leaves out the tests marked slow (whole runs, sweeps, several processes; one smoke test of each kind stays in), make
# test-slow runs only those, make test-all both; CI runs make test and make test-slow.
TEST_JOBS ?= auto
PARALLEL = $(if $(filter 0,$(TEST_JOBS)),,-n $(TEST_JOBS) --maxprocesses 4 --dist loadfile --no-loadscope-reorder)

test: setup
	$(PY) -m pytest -m "not slow" -q --durations=20 $(PARALLEL) $(ARGS)

test-slow: setup
	$(PY) -m pytest -m slow -q --durations=20 $(PARALLEL) $(ARGS)

test-all: setup
	$(PY) -m pytest -q $(PARALLEL) $(ARGS)

# the docs site into site/ (mkdocs.yml; --strict: a broken link or a page outside the nav fails; not -q,
# which hides the warnings that --strict counts)
docs: setup
	NO_MKDOCS_2_WARNING=1 .venv/bin/mkdocs build --strict

bench: setup
	$(PY) scripts/bench_sim.py --quick
	$(PY) scripts/bench_controllers.py --quick

# On a machine with a CUDA GPU: the torch controllers and CE on CUDA vs the CPU, one table (docs/gpu.md, "GPU").
# No setup and no network: the project's venv where there is one, else python3 with torch (offline
# machines; --urdf FILE there). Where ManiSkill and SAPIEN are installed (`make setup`) it runs the
# PhysX GPU parts too (ARGS=--no-physics: not these).
GPU_PY ?= $(shell [ -x $(PY) ] && echo $(PY) || echo python3)
gpu-check:
	$(GPU_PY) scripts/gpu_check.py $(ARGS)
