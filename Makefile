# `make demo` and `make test` each set up a local virtual environment first.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/jaxsqueeze demo --out demo_out

test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile tests

bench: $(STAMP)
	$(BIN)/python benchmarks/precompute.py
	$(BIN)/python benchmarks/squeeze.py
	$(BIN)/python benchmarks/effects.py
	$(BIN)/python benchmarks/accuracy.py

clean:
	rm -rf $(VENV) demo_out
