# Two commands on a fresh clone:  `make run` (the seed paper experiment)  and  `make test`.
# Both run scripts/setup.sh first, which installs whatever is missing (venv, torch, Vulkan).
PY := .venv/bin/python
ARGS ?=

.PHONY: setup run test test-all bench gpu-check
setup:
	@bash scripts/setup.sh

run: setup
	$(PY) -m realize experiment=seed_paper $(ARGS)

test: setup
	$(PY) -m pytest -m "not slow" -q --durations=20 $(ARGS)

test-all: setup
	$(PY) -m pytest -q $(ARGS)

bench: setup
	$(PY) scripts/bench_sim.py --quick
	$(PY) scripts/bench_controllers.py --quick

# On a machine with a CUDA GPU: CUDA tests + seed-paper and journal-budget runs on PhysX GPU, one table
gpu-check: setup
	$(PY) scripts/gpu_check.py $(ARGS)
