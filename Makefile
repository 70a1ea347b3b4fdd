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
# Drake in one process; the same test passes alone). pytest exits 5 when it collected no tests:
# that is a failure here, like any non-zero status, and any failing file fails the run.
test: $(VENV)/.installed-test
	$(BIN)/ruff check .
	@status=0; for file in tests/test_*.py; do \
	    echo "== $$file"; $(BIN)/python -m pytest $$file || status=1; \
	done; \
	if [ $$status -ne 0 ]; then echo "make test: some test files failed (see above)"; fi; \
	exit $$status

clean:
	rm -rf $(VENV) out .pytest_cache
