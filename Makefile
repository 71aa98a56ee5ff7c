# Two entry points: `make demo` and `make test`. Each creates .venv if missing and installs
# what it needs; only Python 3.11 and make are assumed on the machine.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP_RUN := $(VENV)/.installed-run
STAMP_DEV := $(VENV)/.installed-dev

.PHONY: demo test test-readme lint typecheck validate validate-full validate-ci bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# after installing, the on-line system's numba kernels are compiled into the cache once, so that
# the first live session does not fall behind the machine while compiling (decision 1549)
$(STAMP_RUN): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	$(BIN)/millsense warm-up
	touch $@

$(STAMP_DEV): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	$(BIN)/millsense warm-up
	touch $@ $(STAMP_RUN)

demo: $(STAMP_RUN)
	$(BIN)/millsense demo -o demo-output

test: $(STAMP_DEV)
	$(BIN)/python -m pytest
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/mypy src/millsense
	$(BIN)/lint-imports

# The README's walkthrough run verbatim in a copy of the repository (about 4 min; decision 1713):
# CI runs it after `make test`, which skips it.
test-readme: $(STAMP_DEV)
	MILLSENSE_README=1 $(BIN)/python -m pytest tests/test_readme_walkthrough.py

validate: $(STAMP_RUN)
	$(BIN)/millsense validate --quick

# Every case, slow ones included; rewrites docs/validation.md (date and commit in its header).
# Exit status 1 if any case fails (known failures included): the document is written first.
validate-full: $(STAMP_RUN)
	$(BIN)/millsense validate --markdown docs/validation.md

# The slow cases tagged for CI (`ci=True`): a representative acceptance subset, ~15 min on 2 cores.
validate-ci: $(STAMP_RUN)
	$(BIN)/millsense validate --ci

bench: $(STAMP_DEV)
	$(BIN)/python benchmarks/run.py

clean:
	rm -rf $(VENV) demo-output .pytest_cache .mypy_cache .ruff_cache
