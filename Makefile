# Two commands on a fresh machine (only Python 3.11 and pip needed):
#   make run    set up .venv and run the pybullet dry run of fleet.toml
#   make test   set up .venv, lint, build the docs, and run the whole test suite
#   make docs   the docs site, built strictly into site/ (a broken link or a missing page fails)
#   make test-fast   lint and the fast tier (no e2e: dry runs, processes, pybullet), on both cores
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: setup run test test-fast lint docs bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

setup: $(STAMP)

# the dry run's exit status is make run's; then how to call fleet without make
run: $(STAMP)
	@echo "$(BIN)/fleet run --config fleet.toml"
	@$(BIN)/fleet run --config fleet.toml; status=$$?; \
	echo "fleet is in $(BIN): run $(BIN)/fleet --help, or source $(BIN)/activate"; \
	exit $$status

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# the docs site (mkdocs.yml, docs/): strict, so a broken link, anchor or a page left out of the
# nav fails; the reference pages it holds are generated (python -m controller.docs) and checked
# current by tests/unit/test_docs.py
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

# the lockstep tiers (units, dry runs, replays) on both cores, then the real-time processes alone
# (3 workers were no faster than 2 on the whole lockstep pass: 667 s vs 655 s)
test: lint
	$(MAKE) --no-print-directory docs
	$(BIN)/python -m pytest -q -n 2 --dist worksteal -m "not serial" --durations=15
	$(BIN)/python -m pytest -q -m serial --durations=15

test-fast: lint
	$(BIN)/python -m pytest -q -n 2 -m "not e2e"

# every benchmark (bench/stats.py is their statistics; record.py and pages.py their rows' tools)
BENCHES := $(filter-out bench/stats.py bench/record.py bench/pages.py,$(wildcard bench/*.py))
bench: $(STAMP)
	for b in $(BENCHES); do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .pytest_cache runs site
