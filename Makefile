# Everything runs inside the project's virtual environment .venv.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: install run test bench reproduce reproduce-pnnl39 reproduce-pnnl300 clean

install:  ## create .venv and install the project with its test extras
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install -e ".[test]"

run:  ## the main job on the built-in default case: PARS training on the 39-bus FIDVR study
	XLA_FLAGS=--xla_force_host_platform_device_count=2 $(PY) -m experiments.train_39bus --out runs/ieee39

test:  ## the test suite: test files shared by 2 workers, longest first, 2 simulated CPU devices each (tests/conftest.py)
	$(PY) -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder

bench:  ## benchmarks; figures go to benchmarks/cpu/*.json (GPU records: benchmarks/h100/, h200/)
	$(PY) -m experiments.bench.powerflow --out benchmarks/cpu/powerflow.json
	$(PY) -m experiments.bench.sim --out benchmarks/cpu/sim.json
	$(PY) -m experiments.bench.sim --cases ieee39_fidvr ieee300_fidvr --no-andes \
		--batch-sizes 1 8 64 512 2048 --out benchmarks/cpu/sim_fidvr.json
	$(PY) -m experiments.bench.env --out benchmarks/cpu/env.json
	$(PY) -m experiments.bench.train --out benchmarks/cpu/train.json
	$(PY) -m experiments.bench.cmld --out benchmarks/cpu/cmld.json
	$(PY) -m experiments.bench.latency --out benchmarks/cpu/latency.json
	$(PY) -m experiments.bench.profile_step --out benchmarks/cpu/profile_step.json
	$(PY) -m experiments.bench.vecmath --out benchmarks/cpu/vecmath.json
	$(PY) -m experiments.bench.speedup --rounds 1 --out benchmarks/cpu/speedup.json
	$(PY) -m experiments.bench.iterations --out benchmarks/cpu/iterations.json
	$(PY) -m experiments.bench.scale --out benchmarks/cpu/scale.json
	$(PY) -m experiments.bench.ppo --out benchmarks/cpu/ppo.json

reproduce:  ## the paper's 39-bus figures and tables, REPORT.md in results/reproduce39
	XLA_FLAGS=--xla_force_host_platform_device_count=2 $(PY) -m experiments.reproduce \
		--study ieee39_fidvr --out results/reproduce39

reproduce-pnnl39:  ## the paper's settings on the PNNL 39-bus study, REPORT.md in results/pnnl39
	XLA_FLAGS=--xla_force_host_platform_device_count=2 $(PY) -m experiments.reproduce \
		--study studies/ieee39_pnnl.toml --out results/pnnl39

reproduce-pnnl300:  ## the paper's settings on the PNNL 300-bus study, results/pnnl300
	XLA_FLAGS=--xla_force_host_platform_device_count=2 $(PY) -m experiments.reproduce \
		--study studies/ieee300_pnnl.toml --out results/pnnl300

clean:  ## what the project generates (not results/: the committed reports and policies)
	rm -rf $(VENV) runs benchmarks/cpu .pytest_cache .hypothesis build dist *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
