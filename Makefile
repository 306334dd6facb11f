# One command per job. `make test` is what CI runs; `make demo` runs the main job on the sim rig.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DATA ?= data
PYTEST_WORKERS ?= 2

.PHONY: install test test-fast demo bench robustness-cases bench-large check lint types imports schema clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	$(BIN)/python -m pianobot.cli.kernels
	touch $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -n $(PYTEST_WORKERS) -p no:cacheprovider --durations=20

test-fast: $(STAMP)
	$(BIN)/python -m pytest -n $(PYTEST_WORKERS) -p no:cacheprovider -m "not slow and not hardware"

LAST_RUN = $(BIN)/python -c "from pianobot.store import list_runs; print(list_runs('$(DATA)')[-1].run_id)"

demo: $(STAMP)
	$(BIN)/pianobot sweep experiments/quickstart.yaml --data $(DATA)
	$(BIN)/pianobot report $$($(LAST_RUN)) --data $(DATA) --out $(DATA)/quickstart-report.html
	$(BIN)/pianobot runs --data $(DATA)
	@echo "Open $(DATA)/quickstart-report.html in a browser; README.md has a five-minute tour."

bench: $(STAMP)
	mkdir -p benchmarks/results
	@for script in benchmarks/bench_*.py; do \
		echo "== $$script"; \
		$(BIN)/python $$script || exit 1; \
	done

# 100,000 random trials and 1,000,000 for peak RSS, every stream stored (about an hour, ~10 GB
# of scratch data on disk while it runs): results in benchmarks/results/sweep_large.json.
# Issue 13's reported hostile-input cases, one child process each (a few minutes; see the script).
robustness-cases: $(STAMP)
	mkdir -p benchmarks/results
	$(BIN)/python benchmarks/robustness_cases.py

bench-large: $(STAMP)
	mkdir -p benchmarks/results
	$(BIN)/python benchmarks/bench_sweep.py --large

lint: $(STAMP)
	$(BIN)/ruff check pianobot tests benchmarks

types: $(STAMP)
	$(BIN)/mypy pianobot

imports: $(STAMP)
	$(BIN)/lint-imports

check: lint types imports test

schema: $(STAMP)
	$(BIN)/python -m pianobot.spec --write-schemas experiments

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .import_linter_cache
