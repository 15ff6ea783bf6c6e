# bwdesign: every target creates the virtual environment it needs when missing.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.bwdesign-installed
CONFIG ?= configs/paper_experiment.toml
OUT    ?= reports/paper_experiment

.PHONY: install test report lint bench

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

install: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q

report: $(STAMP)
	$(BIN)/bwdesign params --plant $(CONFIG)

lint: $(STAMP)
	$(BIN)/ruff check bwdesign tests analysis
	$(BIN)/ruff format --check bwdesign tests analysis

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_observers.py
	$(BIN)/python benchmarks/bench_certify.py
