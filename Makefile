# PopNavShift: two commands on a fresh clone with python3 and make.
#   make run   — create .venv, install, run the default study (offline)
#   make test  — create/refresh .venv with dev extras, lint, type-check, run the tests
#                (two worker processes, one test module each at a time: pytest-xdist)
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STUDY ?= study

.PHONY: run test install install-dev lint typecheck clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-dev: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $@ $(VENV)/.installed

install: $(VENV)/.installed
install-dev: $(VENV)/.installed-dev

run: install
	$(BIN)/popnavshift run --out $(STUDY)

lint: install-dev
	$(BIN)/ruff check

typecheck: install-dev
	$(BIN)/mypy

test: lint typecheck
	$(BIN)/python -m pytest -n 2 --dist loadfile

clean:
	rm -rf $(VENV) $(STUDY) .pytest_cache .ruff_cache .mypy_cache
