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

test:  ## the test suite: test files shared by 2 workers, 2 simulated CPU devices each (tests/conftest.py)
	$(PY) -m pytest -q -n 2 --dist loadfile

bench:  ## benchmarks; figures go to bench_results/*.json
	$(PY) -m experiments.bench_powerflow --out bench_results/powerflow.json
	$(PY) -m experiments.bench_sim --out bench_results/sim.json
	$(PY) -m experiments.bench_sim --cases ieee39_fidvr ieee300_fidvr --no-andes \
		--batch-sizes 1 8 64 512 2048 --out bench_results/sim_fidvr.json
	$(PY) -m experiments.bench_env --out bench_results/env.json
	$(PY) -m experiments.bench_train --out bench_results/train.json
	$(PY) -m experiments.bench_cmld --out bench_results/cmld.json
	$(PY) -m experiments.bench_latency --out bench_results/latency.json
	$(PY) -m experiments.profile_step --out bench_results/profile_step.json
	$(PY) -m experiments.bench_vecmath --out bench_results/vecmath.json
	$(PY) -m experiments.bench_speedup --rounds 1 --out bench_results/speedup.json
	$(PY) -m experiments.bench_scale --out bench_results/scale.json

reproduce:  ## the paper's 39-bus figures and tables, REPORT.md in results/reproduce39
	XLA_FLAGS=--xla_force_host_platform_device_count=2 $(PY) -m experiments.reproduce \
		--study ieee39_fidvr --out results/reproduce39

reproduce-pnnl39:  ## the paper's settings on the PNNL 39-bus study, REPORT.md in results/pnnl39
	XLA_FLAGS=--xla_force_host_platform_device_count=2 $(PY) -m experiments.reproduce \
		--study studies/ieee39_pnnl.toml --out results/pnnl39

reproduce-pnnl300:  ## the paper's settings on the PNNL 300-bus study, results/pnnl300
	XLA_FLAGS=--xla_force_host_platform_device_count=2 $(PY) -m experiments.reproduce \
		--study studies/ieee300_pnnl.toml --out results/pnnl300

clean:
	rm -rf $(VENV) results bench_results .pytest_cache
