# Two commands on a fresh machine: `make demo` (main job) and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test install bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	# compile the modules' bytecode and the numba kernels now (cached on disk), not on a user's first command
	$(BIN)/python -m multilat.warmup
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/multilat demo --out demo-report

# two pytest workers (pytest-xdist, the test extra): ~5.5 min here instead of ~8 (2 cores, quiet);
# one BLAS thread per worker, set once in tests/conftest.py (not 2 workers x 2 BLAS threads on 2 cores)
test: $(STAMP)
	$(BIN)/python -m pytest -n 2

bench: $(STAMP)
	$(BIN)/python benchmarks/run.py

clean:
	rm -rf $(VENV) demo-report .pytest_cache
