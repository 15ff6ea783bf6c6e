# bwdesign: every target creates the virtual environment it needs when missing.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.bwdesign-installed
CONFIG ?= configs/paper_experiment.toml
OUT    ?= reports/paper_experiment

.PHONY: install test report reports paper lint bench benchmark dist identify audit docs

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

install: $(STAMP)

# PYTEST_ARGS: extra pytest options (.ci/run passes -m '' and --durations).
# -n auto: one pytest-xdist worker per core. --dist loadfile runs each test module on
# one worker, so its module fixtures are computed once; --no-loadscope-reorder gives the
# modules out in the order tests/conftest.py sets (the heaviest first).
# compileall: the package's bytecode written once (only what changed), so the suite's
# fresh interpreters read it instead of compiling bwdesign each (an editable install
# writes none, and PYTHONDONTWRITEBYTECODE=1 stops Python writing it; measured on a
# fresh clone: 116.9 s without, 107.2 s with).
# PYTHONDONTWRITEBYTECODE= (empty: unset for Python) lets pytest keep the test modules and
# the bwdesign plugin's modules with their assertions rewritten (in __pycache__, ignored by
# git); with the variable set, every worker and every pytest the tests start rewrites
# about 290 modules again (4 s each on this machine).
test: $(STAMP)
	$(BIN)/python -m compileall -q bwdesign > /dev/null
	PYTHONDONTWRITEBYTECODE= $(BIN)/python -m pytest -q -n auto --dist loadfile \
	  --no-loadscope-reorder $(PYTEST_ARGS)

# the main job: the certified-gains report for the default stage
report: $(STAMP)
	$(BIN)/bwdesign report --config $(CONFIG) --out $(OUT)

# from bench data to a stage file and its certified gains: DATA (t,u,y CSV or NPZ),
# optional VALID; writes $(IDENT)/stage.toml, $(IDENT)/identification/ and $(IDENT)/certified/
DATA  ?= examples/identification/train.csv
VALID ?= examples/identification/valid.csv
IDENT ?= reports/identified
identify: $(STAMP)
	$(BIN)/bwdesign identify --data $(DATA) $(if $(VALID),--validate $(VALID)) \
	  --out $(IDENT)/stage.toml --report $(IDENT)/identification
	$(BIN)/bwdesign report --config $(IDENT)/stage.toml --out $(IDENT)/certified

# reports for every bundled stage configuration
reports: $(STAMP)
	for c in configs/*.toml; do \
	  $(BIN)/bwdesign report --config $$c --out reports/$$(basename $$c .toml) || exit $$?; \
	done

# the paper reproduction: observer comparison (Section 4.1) and Tables 1-2, the
# baselines beside the observer loops (issue 29), and the certified robust bounds beside
# the worst cases found on every bundled stage (issue 27)
paper: $(STAMP)
	$(BIN)/python analysis/observer_comparison.py --out reports/observers
	$(BIN)/python analysis/paper_tables.py --out reports/paper
	$(BIN)/python analysis/baselines_table.py --out reports/baselines
	$(BIN)/python analysis/robust_bounds.py --out reports/robust_bounds

lint: $(STAMP)
	$(BIN)/ruff check bwdesign tests analysis benchmarks examples docs/conf.py docs/api_names.py
	$(BIN)/ruff format --check bwdesign tests analysis benchmarks examples docs/conf.py docs/api_names.py

# every benchmark runs; the exit status is 1 if any missed its target (or failed)
BENCHES = observers certify codegen sweep identify report
bench: $(STAMP)
	@failed=""; for b in $(BENCHES); do \
	  $(BIN)/python benchmarks/bench_$$b.py || failed="$$failed $$b"; done; \
	if [ -n "$$failed" ]; then echo "bench: target missed or failed in:$$failed"; exit 1; fi

# the hysteretic benchmark (Noel and Schoukens 2016) with the structural form: identification
# time and validation RMS errors beside the published figures (SEEDS records)
SEEDS ?= 1
benchmark: $(STAMP)
	$(BIN)/python benchmarks/boucwen_benchmark.py --seeds $(SEEDS)

# the sdist and the wheel (the wheel built from the sdist) into dist/, checked as an index would
dist: $(STAMP)
	rm -rf dist
	$(BIN)/python -m build --outdir dist .
	$(BIN)/twine check --strict dist/*

# seeded audit of certify/synthesize against an exact mpmath check (results in reports/audit/)
audit: $(STAMP)
	$(BIN)/python analysis/certify_audit.py --workers 2 --out reports/audit

# the documentation site into docs/_build/html: docs/ is copied into docs/_build/src, so
# what the build generates (API pages, the gallery run) stays under docs/_build/; warnings
# are errors (-W --keep-going reports all of them, then fails)
SPHINXOPTS ?= -W --keep-going -q
docs: $(STAMP)
	rm -rf docs/_build/src docs/_build/html docs/_build/doctrees
	$(BIN)/python -c "import shutil; shutil.copytree('docs', 'docs/_build/src', ignore=shutil.ignore_patterns('_build', '__pycache__'))"
	$(BIN)/python -m sphinx -b html $(SPHINXOPTS) -d docs/_build/doctrees docs/_build/src docs/_build/html
