# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-campaign test-full bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/hapstab reproduce all --out out/
	@echo "Fig. 5 and Fig. 6 written to $(CURDIR)/out/: fig5.png fig5.svg fig5.csv fig6.png fig6.svg fig6.csv"

# Bytecode caches (__pycache__/, git-ignored) are written even where the machine sets
# PYTHONDONTWRITEBYTECODE (this one does): without them every pytest worker and every
# command a test starts compiles hapstab and the tests again (assertion rewriting
# included), about 7 s per worker's collection and 0.2 s per command.
PYCACHE := env -u PYTHONDONTWRITEBYTECODE

# lint (ruff), types (mypy on src/, its modules checked by one worker process per core:
# 23-29 -> 14-18 s on a clean cache on 2 cores, measured), then the suite (warnings are
# errors: pyproject)
test: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/mypy -n auto src
	$(PYCACHE) $(BIN)/python -m pytest -n auto --dist loadgroup

# the rest of every seeded draw and the long campaigns (tests/lanes.py): with `make test`,
# each case once
test-campaign: $(STAMP)
	$(PYCACHE) $(BIN)/python -m pytest -n auto --dist loadgroup -m 'slow or campaign'

# everything: every draw whole, slow and campaign included
test-full: $(STAMP)
	$(PYCACHE) HAPSTAB_CAMPAIGN=full $(BIN)/python -m pytest -n auto --dist loadgroup \
		-m 'slow or campaign or not (slow or campaign)'

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,bench]'
	$(BIN)/python benchmarks/bench_core.py
	$(BIN)/python benchmarks/bench_boundary.py
	$(BIN)/python benchmarks/bench_circle.py
	$(BIN)/python benchmarks/bench_simulate.py
	$(BIN)/python benchmarks/bench_regions.py
	$(BIN)/python benchmarks/bench_delay.py
	$(BIN)/python benchmarks/bench_budget.py
	$(BIN)/python benchmarks/bench_robust.py
	$(BIN)/python benchmarks/bench_many.py
	$(BIN)/python benchmarks/bench_sweep.py
	$(BIN)/python benchmarks/bench_explorer.py
	$(BIN)/python benchmarks/bench_network_all.py

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis docs/_build docs/gallery docs/reference/generated

# the documentation site (docs/): offline, warnings (unresolved references included) are errors
.PHONY: docs
docs: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[docs]'
	$(BIN)/python -m sphinx -W --keep-going -n -b html docs docs/_build/html
	@echo "documentation written to $(CURDIR)/docs/_build/html/index.html"
