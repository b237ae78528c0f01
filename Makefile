# plenocli: `make demo` sets everything up and runs the pipelines on the shipped fixtures;
# `make test` runs the test suite. Both create .venv on first use.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
DEMO   := out/demo

.PHONY: all demo test test-fast bench fixtures lint clean

all: test

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

fixtures: $(STAMP)
	test -f fixtures/dualpixel/capture.dng || $(BIN)/plenocli simulate dualpixel -o fixtures/dualpixel --seed 1

demo: $(STAMP) fixtures
	$(BIN)/plenocli run configs/demo_dualpixel.yaml
	@echo
	@echo "demo results and PNG previews are in $(DEMO)/:"
	@find $(DEMO) -name '*.png' -o -name '*.tif' -o -name '*.yaml' -o -name '*.json' | sort | sed 's/^/  /'

test: $(STAMP)
	$(BIN)/python -m pytest -q

test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow"

bench: $(STAMP)
	for b in bench/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

lint: $(STAMP)
	$(BIN)/ruff check plenocli tests bench

clean:
	rm -rf out .pytest_cache
