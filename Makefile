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
	$(BIN)/python -m pip install --quiet -e '.[dev,dask]'
	$(BIN)/python -m plenocli.warmup  # numba kernels compiled once, into their cache
	touch $@

# Simulated captures with ground truth for the demos (seeded: the same files every time).
SIM       := out/fixtures
SIM_KINDS := dualpixel-prism dualpixel-white dualpixel-masked quadpixel-pyramid \
             raytrix-prism raytrix-white dualpixel-ghost quadpixel-ghost raytrix-ghost
SIM_ARGS_dualpixel-prism   := --pixels 768
SIM_ARGS_dualpixel-white   := --pixels 768
SIM_ARGS_dualpixel-masked  := --pixels 768 --param crosstalk=0.2
SIM_ARGS_quadpixel-pyramid := --pixels 1024
SIM_ARGS_raytrix-prism     := --pixels 1200
SIM_ARGS_raytrix-white     := --pixels 1200
SIM_ARGS_dualpixel-ghost   := --pixels 768
SIM_ARGS_quadpixel-ghost   := --pixels 1024
SIM_ARGS_raytrix-ghost     := --pixels 1200

$(SIM)/%/truth.json: $(STAMP)
	$(BIN)/plenocli simulate $* -o $(SIM)/$* $(SIM_ARGS_$*) -q

fixtures: $(STAMP) $(SIM_KINDS:%=$(SIM)/%/truth.json)
	test -f fixtures/dualpixel/capture.dng || $(BIN)/plenocli simulate dualpixel -o fixtures/dualpixel --seed 1

DEMOS := demo_dualpixel dualpixel_stitch quadpixel_stitch raytrix_r5

demo: $(STAMP) fixtures
	for c in $(DEMOS); do echo "== configs/$$c.yaml"; $(BIN)/plenocli run configs/$$c.yaml || exit 1; done
	@echo
	@echo "demo results and PNG previews are in $(DEMO)/ (panoramas: $(DEMO)/*/panorama.png):"
	@find $(DEMO) -name '*.png' | sort | sed 's/^/  /'

# two processes (the CI machine's cores), a test module in one process at a time: its
# module-scoped fixtures are built once
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadscope

test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow"

bench: $(STAMP)
	for b in bench/bench_*.py; do echo "== $$b"; PYTHONPATH=. $(BIN)/python $$b || exit 1; done

# ruff (with complexity ceilings, see pyproject.toml), the file/function length rules and the
# layers (imports point down, no stage imports a stage, only the CLI imports click)
lint: $(STAMP)
	$(BIN)/ruff check plenocli tests bench
	$(BIN)/python -m pytest -q -p no:cacheprovider tests/test_code_size.py tests/test_layers.py

clean:
	rm -rf out .pytest_cache
