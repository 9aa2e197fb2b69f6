# Two entry points: `make run` (the main job) and `make test` (the whole test suite).
# Both create .venv from scratch on a fresh machine and install the package with its dev extras, at the exact
# versions of constraints.txt.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test env lint bench wheel-smoke clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[dev]'
	touch $(STAMP)

env: $(STAMP)

run: $(STAMP)
	$(BIN)/peano-bayes run

# Two workers (the CI machine's two cores); tests sharing an expensive fixture or compilation carry one
# xdist_group, so one worker builds it once.
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadgroup

# The built wheel, installed into a fresh venv outside the checkout and used from there (CI runs it too).
wheel-smoke:
	bash .ci/wheel_smoke

lint: $(STAMP)
	$(BIN)/ruff check .

bench: $(STAMP)
	$(BIN)/python experiments/bench_forward.py

clean:
	rm -rf $(VENV) build *.egg-info
