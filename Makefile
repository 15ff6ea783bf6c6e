# bwdesign: every target creates the virtual environment it needs when missing.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.bwdesign-installed
CONFIG ?= configs/paper_experiment.toml
OUT    ?= reports/paper_experiment

.PHONY: install test report reports paper lint bench audit

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

install: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q

# the main job: the certified-gains report for the default stage
report: $(STAMP)
	$(BIN)/bwdesign report --config $(CONFIG) --out $(OUT)

# reports for every bundled stage configuration
reports: $(STAMP)
	for c in configs/*.toml; do \
	  $(BIN)/bwdesign report --config $$c --out reports/$$(basename $$c .toml) || exit $$?; \
	done

# the paper reproduction: observer comparison (Section 4.1) and Tables 1-2
paper: $(STAMP)
	$(BIN)/python analysis/observer_comparison.py --out reports/observers
	$(BIN)/python analysis/paper_tables.py --out reports/paper

lint: $(STAMP)
	$(BIN)/ruff check bwdesign tests analysis benchmarks
	$(BIN)/ruff format --check bwdesign tests analysis benchmarks

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_observers.py
	$(BIN)/python benchmarks/bench_certify.py

# seeded audit of certify/synthesize against an exact mpmath check (results in reports/audit/)
audit: $(STAMP)
	$(BIN)/python analysis/certify_audit.py --workers 2 --out reports/audit
