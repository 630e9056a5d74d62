# Quick start: `make demo` (install + the main job) and `make test` (install + the default test suite).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
PIP := $(BIN)/python -m pip --disable-pip-version-check -q

.PHONY: demo test system-deps test-slow test-reference parity reference bench clean lock

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -U pip

# One stamp per set of extras, so that `make test` after `make demo` only adds what is missing.
# constraints.txt pins every package to the versions behind the committed results (see its header).
$(VENV)/.installed-base: pyproject.toml constraints.txt | $(BIN)/python
	$(PIP) install -c constraints.txt -e .
	touch $@

# The tests run every listed env id, so they take the box2d and mujoco extras too, and video for `ermrl video`.
$(VENV)/.installed-test: pyproject.toml constraints.txt | $(BIN)/python
	$(PIP) install -c constraints.txt -e '.[test,box2d,mujoco,video,workers,dashboard]'
	touch $@

# MuJoCo renders videos headless through OSMesa (Debian's libosmesa6; about 130 MB installed with LLVM). As root
# (CI) it is installed when missing; anyone else gets a note, and the MuJoCo video test is skipped without it or EGL.
GL_PACKAGES := libosmesa6
# Pages (the dashboard) are checked in headless Chromium (Debian's chromium, about 410 MB installed), the same way.
BROWSER_PACKAGES := chromium
# The multi-worker tests start a throwaway PostgreSQL server from Debian's binaries (initdb and pg_ctl, which Debian
# keeps in /usr/lib/postgresql/VERSION/bin), the same way; without them those tests are skipped.
PG_PACKAGES := postgresql
system-deps:
	@if $(PYTHON) -c "import ctypes.util, sys; sys.exit(ctypes.util.find_library('OSMesa') is None)"; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing $(GL_PACKAGES) (headless MuJoCo rendering)"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $(GL_PACKAGES) >/dev/null; \
	else \
		echo "note: MuJoCo videos render headless with OSMesa: run 'sudo apt-get install $(GL_PACKAGES)' (Debian/Ubuntu); without it (or EGL) the MuJoCo video test is skipped"; \
	fi
	@if command -v chromium >/dev/null; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing $(BROWSER_PACKAGES) (headless browser checks)"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $(BROWSER_PACKAGES) >/dev/null; \
	else \
		echo "note: the dashboard page is checked in headless Chromium: run 'sudo apt-get install $(BROWSER_PACKAGES)' (Debian/Ubuntu); without it that test is skipped"; \
	fi
	@if command -v initdb >/dev/null || ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing $(PG_PACKAGES) (the multi-worker tests' PostgreSQL server)"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $(PG_PACKAGES) >/dev/null; \
	else \
		echo "note: the multi-worker tests start a PostgreSQL server: run 'sudo apt-get install $(PG_PACKAGES)' (Debian/Ubuntu); without it they are skipped"; \
	fi

# The reference pipeline (SB3, sb3-contrib, ReservoirPy) lives in its own venv so that the default one never holds torch.
# torch first, pinned, so that pip takes the CPU wheel instead of a multi-GB CUDA build.
REF_VENV ?= .venv-ref
$(REF_VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(REF_VENV)
	$(REF_VENV)/bin/python -m pip --disable-pip-version-check -q install torch==2.13.0
	$(REF_VENV)/bin/python -m pip --disable-pip-version-check -q install -e '.[test,reference,box2d,mujoco]'
	touch $@

# The main job: a small evolution on masked CartPole (3 CMA-ES generations, embedded SQLite in runs/demo/),
# a short test phase of the best Φ against PPO, and the HTML report. Rerunning resumes the finished study.
demo: $(VENV)/.installed-base
	$(BIN)/ermrl evolve --env CartPoleNoVel-v1 --trials 18 --seeds 3 --timesteps 50000 --fixed-iss 1.0 --study demo
	$(BIN)/ermrl test --study demo --seeds 3 --timesteps 100000
	$(BIN)/ermrl report --study demo

# Two pytest workers (pytest-xdist), one per core of the CI machine: `make test TEST_WORKERS=4` on a bigger one.
TEST_WORKERS ?= 2
test: $(VENV)/.installed-test system-deps
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --durations=25

# Slow tests: the MuJoCo v4 smoke tests (and any long learning run marked slow).
test-slow: $(VENV)/.installed-test
	$(BIN)/python -m pytest -q -m slow

reference: $(REF_VENV)/.installed

# Rewrites constraints.txt from the test venv (its header kept): run it in a venv that holds nothing but this
# install, and commit it together with the reruns that the new versions call for.
lock: $(VENV)/.installed-test
	{ grep '^#' constraints.txt; $(PIP) freeze --exclude-editable; } > constraints.txt.new
	mv constraints.txt.new constraints.txt

# Tests that need torch and SB3: the wrapper under SB3, PPO parity with SB3 and PPO-LSTM parity with sb3-contrib
# RecurrentPPO (about 30 min on 2 cores).
test-reference: $(REF_VENV)/.installed
	$(REF_VENV)/bin/python -m pytest -q -m reference

# PPO parity with SB3 on CartPole-v1 and Pendulum-v1 (5 seeds x 100k each; about 17 min on 2 cores), and PPO-LSTM
# parity with sb3-contrib's RecurrentPPO on CartPoleNoVel-v1 (5 seeds x 50k; about 12 min on 2 idle cores).
parity: $(REF_VENV)/.installed
	$(REF_VENV)/bin/python -m pytest -q -s -m reference tests/test_parity_sb3.py tests/test_parity_recurrent.py

bench: $(VENV)/.installed-test $(REF_VENV)/.installed
	$(BIN)/python benchmarks/throughput.py --repeats 3 --reference-python $(REF_VENV)/bin/python
	$(BIN)/python benchmarks/throughput.py --env HalfCheetah-v5 --sizes 6 21 --repeats 3 --reference-agents 2 --reference-python $(REF_VENV)/bin/python
	$(BIN)/python benchmarks/throughput.py --env Humanoid-v5 --sizes 6 21 --repeats 3 --reference-agents 2 --reference-python $(REF_VENV)/bin/python

clean:
	rm -rf $(VENV) runs .pytest_cache
