# Quick start: `make demo` (install + the main job) and `make test` (install + the default test suite).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
PIP := $(BIN)/python -m pip --disable-pip-version-check -q

.PHONY: demo test test-slow test-reference reference bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -U pip

# One stamp per set of extras, so that `make test` after `make demo` only adds what is missing.
$(VENV)/.installed-base: pyproject.toml | $(BIN)/python
	$(PIP) install -e .
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(PIP) install -e '.[test]'
	touch $@

# The reference pipeline (SB3 + ReservoirPy) lives in its own venv so that the default one never holds torch.
# torch first, pinned, so that pip takes the CPU wheel instead of a multi-GB CUDA build.
REF_VENV ?= .venv-ref
$(REF_VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(REF_VENV)
	$(REF_VENV)/bin/python -m pip --disable-pip-version-check -q install torch==2.13.0
	$(REF_VENV)/bin/python -m pip --disable-pip-version-check -q install -e '.[test,reference,mujoco]'
	touch $@

# The main job: a small evolution on masked CartPole (3 CMA-ES generations, embedded SQLite in runs/demo/),
# a short test phase of the best Φ against PPO, and the HTML report. Rerunning resumes the finished study.
demo: $(VENV)/.installed-base
	$(BIN)/ermrl evolve --env CartPoleNoVel-v1 --trials 18 --seeds 3 --timesteps 50000 --fixed-iss 1.0 --study demo
	$(BIN)/ermrl test --study demo --seeds 3 --timesteps 100000
	$(BIN)/ermrl report --study demo

test: $(VENV)/.installed-test
	$(BIN)/python -m pytest -q

# Long learning runs (full-size budgets); minutes each.
test-slow: $(VENV)/.installed-test
	$(BIN)/python -m pytest -q -m slow || [ $$? -eq 5 ]  # 5: no slow test collected yet

reference: $(REF_VENV)/.installed

# Tests that need torch and SB3 (the wrapper under SB3; SB3 parity comes with issue 4).
test-reference: $(REF_VENV)/.installed
	$(REF_VENV)/bin/python -m pytest -q -m reference

bench: $(VENV)/.installed-test $(REF_VENV)/.installed
	$(BIN)/python benchmarks/throughput.py --repeats 3 --reference-python $(REF_VENV)/bin/python

clean:
	rm -rf $(VENV) runs .pytest_cache
