# Set-up and everyday commands. `make demo` and `make test` work on a fresh clone.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test lint format bench clean install docs-results

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install --quiet -e ".[dev]"
	# bytecode of the (editable) sources, written even where PYTHONDONTWRITEBYTECODE is
	# set (containers): every start-up would otherwise compile the package again
	$(PY) -m compileall -q src
	$(VENV)/bin/tobitkf warmup --jobs 2  # compile the numba kernels once, into the cache
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/tobitkf demo --out demo-output

test: $(STAMP)
	$(PY) -m ruff check src tests benchmarks tools
	$(PY) -m ruff format --check src tests benchmarks tools
	# the slowest tests listed at the end: CI has 20 minutes on 2 cores
	$(PY) -m pytest -q -p no:cacheprovider --durations=15

lint: $(STAMP)
	$(PY) -m ruff check src tests benchmarks tools

format: $(STAMP)
	$(PY) -m ruff format src tests benchmarks tools
	$(PY) -m ruff check --fix src tests benchmarks tools

bench: $(STAMP)
	$(PY) -m pip install --quiet -e ".[bench]"
	$(PY) tools/docs_results.py --bench

docs-results: $(STAMP)
	$(PY) tools/docs_results.py

clean:
	rm -rf $(VENV) demo-output build *.egg-info src/*.egg-info .pytest_cache
