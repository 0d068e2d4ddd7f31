# Two commands on a fresh machine (only Python 3.11 and pip needed):
#   make run    set up .venv and run the pybullet dry run of fleet.toml
#   make test   set up .venv, lint, and run the whole test suite
#   make test-fast   lint and the fast tier (no e2e: dry runs, processes, pybullet), ~1 min
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: setup run test test-fast lint bench clean

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

# the lockstep tiers (units, dry runs, replays) on both cores, then the real-time processes alone
# (3 workers were no faster than 2 on the whole lockstep pass: 667 s vs 655 s)
test: lint
	$(BIN)/python -m pytest -q -n 2 --dist worksteal -m "not serial" --durations=15
	$(BIN)/python -m pytest -q -m serial --durations=15

test-fast: lint
	$(BIN)/python -m pytest -q -m "not e2e"

bench: $(STAMP)
	for b in bench/*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .pytest_cache runs
