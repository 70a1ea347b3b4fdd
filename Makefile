# The two set-up commands. Each creates .venv on a fresh machine (Python 3.11+) and
# installs what it needs; a re-run only reinstalls when pyproject.toml changed.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: demo test clean

$(BIN)/python:
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "hydrotact needs Python 3.11 or newer: run make PYTHON=python3.11 ...")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@ $(VENV)/.installed

demo: $(VENV)/.installed
	$(BIN)/hydrotact demo --output out

# Lint first (ruff, configured in pyproject.toml); a lint error fails the run before any
# test. Then each test file runs in a fresh process: over one long session XLA's CPU
# compiler crashed (SIGSEGV while compiling, after ~200 tests of JAX, VTK rendering and
# Drake in one process; the same test passes alone). A test process keeps about one core
# busy (XLA compiles on one thread), so TEST_JOBS files run at once (xargs -P); each
# file's output is printed whole when it ends, longest files first so the run ends
# together (an order that also lets the notebooks reuse the programs the first files
# compiled: notebooks first cost them 70 CPU-s more, 2026-12-06). pytest exits 5 when
# it collected no tests: that is a failure here, like any non-zero status, and any
# failing file fails the run (and is named at the end).
# Each file's line gives the CPU time its processes used (the shell's `times`; a Ray
# cluster's daemons are not its children and are not counted): beside another file,
# wall time says little about a file's own cost.
# All test processes share one persistent XLA compilation cache, made anew each run
# (locked: its size is bounded): files, notebooks and experiments compile many of the
# same programs, and one hydrotact cache (meshes, elastic fields, unit responses).
# (XLA's backend optimisation level 0 was tried, 2026-12-06: test_sim alone 29 % less
# CPU, but the whole suite no faster: the files that run long solves slowed as much;
# benchmarks/RESULTS.md.)
TEST_JOBS ?= 2
TEST_LOGS := .pytest-logs
TEST_FIRST := tests/test_contact.py tests/test_datasets.py tests/test_taxel.py tests/test_forward_model.py tests/test_notebooks_and_experiments.py tests/test_press_fit.py
TEST_FILES := $(TEST_FIRST) $(filter-out $(TEST_FIRST),$(sort $(wildcard tests/test_*.py)))

test: $(VENV)/.installed-test
	$(BIN)/ruff check .
	@rm -rf $(TEST_LOGS) && mkdir -p $(TEST_LOGS)
	@export JAX_COMPILATION_CACHE_DIR=$(CURDIR)/$(TEST_LOGS)/xla-cache JAX_COMPILATION_CACHE_MAX_SIZE=4000000000 HYDROTACT_TEST_CACHE_DIR=$(CURDIR)/$(TEST_LOGS)/hydrotact-cache; printf '%s\n' $(TEST_FILES) | xargs -P $(TEST_JOBS) -I FILE sh -c '\
	    log=$(TEST_LOGS)/$$(basename FILE .py).log; echo "== FILE started"; \
	    $(BIN)/python -m pytest --durations=8 FILE > $$log 2>&1; status=$$?; times > $$log.cpu; \
	    echo "== FILE (exit $$status; CPU time of its processes, user and system: $$(tail -n 1 $$log.cpu))"; cat $$log; \
	    [ $$status -eq 0 ] || touch $$log.failed; exit 0'
	@failed=$$(ls $(TEST_LOGS) | sed -n "s/\.log\.failed$$//p"); \
	if [ -n "$$failed" ]; then echo "make test: these test files failed (see above):" $$failed; exit 1; fi; \
	echo "make test: every test file passed"

clean:
	rm -rf $(VENV) out .pytest_cache .pytest-logs
