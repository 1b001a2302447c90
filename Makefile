# Set-up and entry points. Both targets create .venv when missing and install everything.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev,ni,visa,tdms,mdf]'
	$(BIN)/python -c 'from processing._welch_kernel import compile_ahead; compile_ahead()'
	touch $(STAMP)

# Every process the tests and the demo start (the command line, the mock benches, Dask's
# workers) imports the project: its bytecode compiled once here, not in each process (an
# environment with PYTHONDONTWRITEBYTECODE set never writes it; about 0.8 s a process).
BYTECODE := $(BIN)/python -m compileall -q app drivers processing hardware_mocks benchmarks

demo: $(STAMP)
	$(BYTECODE)
	$(BIN)/insitu demo

test: $(STAMP)
	$(BIN)/ruff check app drivers processing hardware_mocks tests benchmarks
	$(BIN)/lint-imports
	$(BIN)/mypy
	$(BYTECODE)
	$(BIN)/python -m pytest -n auto --maxschedchunk 1

bench: $(STAMP)
	$(BIN)/python benchmarks/identify.py

clean:
	rm -rf $(VENV) build *.egg-info
