# etdmp_ros: `make demo` and `make test` build the Python environment in .venv/ themselves.
# Needs only Python >= 3.11 (with its venv module: Debian/Ubuntu package python3-venv) and make.

PYTHON      ?= python3
VENV        := .venv
VENV_PY     := $(VENV)/bin/python
PIP_VERSION := 26.3
# Stamp: the venv is (re)installed only when the lock or the package metadata changes.
STAMP       := $(VENV)/.installed
PYTEST_ARGS ?= -q test
LETTERS_DIR ?= ../shared/data/pbdlib_2Dletters
BENCH       := test/benchmarks/bench_core.py

.PHONY: venv test demo docs bench bench-core clean distclean help
.DEFAULT_GOAL := help

help:
	@echo "make demo       headless demo (builds .venv/ on first use)"
	@echo "make test       whole test suite (builds .venv/ on first use); e.g. PYTEST_ARGS='-x test'"
	@echo "make docs       regenerate the README pictures in docs/img/"
	@echo "make bench      core benchmarks vs movement-primitives and pydmps ($(BENCH), own .venv-bench/)"
	@echo "make venv       only build .venv/ (pinned requirements.txt + this package, editable)"
	@echo "make clean      remove build outputs and caches; make distclean also removes .venv*/"

venv: $(STAMP)

$(VENV_PY):
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null || { \
	  echo "error: '$(PYTHON)' must be Python >= 3.11 (found: $$($(PYTHON) --version 2>&1))." >&2; \
	  echo "       Install one, or run e.g. 'make PYTHON=python3.12 $(MAKECMDGOALS)'." >&2; exit 1; }
	@$(PYTHON) -m venv $(VENV) || { rm -rf $(VENV); \
	  echo "error: '$(PYTHON) -m venv' failed. On Debian/Ubuntu: sudo apt-get install python3-venv" >&2; \
	  exit 1; }

$(STAMP): requirements.txt setup.py setup.cfg | $(VENV_PY)
	@echo "Installing pinned requirements into $(VENV)/ (about a minute the first time)..."
	$(VENV_PY) -m pip install --quiet --disable-pip-version-check "pip==$(PIP_VERSION)"
	$(VENV_PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	$(VENV_PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $@

test: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) -m pytest $(PYTEST_ARGS)

demo: $(STAMP)
	@if [ -d "$(LETTERS_DIR)" ]; then \
	  echo "Reproducing the paper's letter experiments from $(LETTERS_DIR) -> out/reproduce/"; \
	  MUJOCO_GL=egl $(VENV)/bin/etdmp reproduce --letters-dir "$(LETTERS_DIR)" \
	    --table "$(LETTERS_DIR)/table2.json" --out out/reproduce; \
	else \
	  echo "$(LETTERS_DIR) not found (the paper's letter data set sits beside the repository);"; \
	  echo "generalizing the built-in letter G instead -> out/demo/"; \
	  mkdir -p out/demo; \
	  MUJOCO_GL=egl $(VENV)/bin/etdmp generalize --skill G --start 5 5 --goal 0 0 --method etdmp \
	    --plot out/demo/G.png --json out/demo/G.json; \
	fi

# README pictures: the paper reproduction's figures and one built-in generalization.
docs: $(STAMP)
	$(VENV)/bin/etdmp reproduce --letters-dir "$(LETTERS_DIR)" \
	  --table "$(LETTERS_DIR)/table2.json" --out out/reproduce
	mkdir -p docs/img
	cp out/reproduce/fig5_generalization.png out/reproduce/fig7_8_obstacles.png \
	  out/reproduce/fig13_nrmse.png docs/img/
	$(VENV)/bin/etdmp generalize --skill G --start -6 4 --goal 0 0 --obstacle -7.6 -4.4 \
	  --plot docs/img/generalize_G.png

# The benchmark's own environment: the project's pins plus the peer libraries it compares
# against (movement-primitives, pydmps), which never enter .venv/.
BENCH_VENV  := .venv-bench
BENCH_STAMP := $(BENCH_VENV)/.installed
BENCH_REQ   := test/benchmarks/requirements-bench.txt
BENCH_ARGS  ?=

$(BENCH_STAMP): requirements.txt $(BENCH_REQ) setup.py setup.cfg
	$(PYTHON) -m venv $(BENCH_VENV)
	$(BENCH_VENV)/bin/python -m pip install --quiet --disable-pip-version-check "pip==$(PIP_VERSION)"
	$(BENCH_VENV)/bin/python -m pip install --quiet --disable-pip-version-check \
	  -r requirements.txt -r $(BENCH_REQ)
	$(BENCH_VENV)/bin/python -m pip install --quiet --disable-pip-version-check \
	  --no-deps --no-build-isolation -e .
	@touch $@

bench: bench-core

bench-core: $(BENCH_STAMP)
	$(BENCH_VENV)/bin/python $(BENCH) $(BENCH_ARGS)

clean:
	rm -rf out build install log .pytest_cache *.egg-info
	find . -path ./.git -prune -o -path './.venv*' -prune -o \
	  \( -name __pycache__ -o -name '*.nbi' -o -name '*.nbc' \) -print0 | xargs -0 rm -rf

distclean: clean
	rm -rf $(VENV) .venv-*
