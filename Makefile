# One-command set-up: `make eval` runs the default evaluation, `make test` runs the tests.
# torch is installed first and pinned: an unpinned torch pulls a multi-GB CUDA build.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
TORCH_VERSION ?= 2.13.0

.PHONY: setup eval test lint bench wheel clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet torch==$(TORCH_VERSION)
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $@

# The Ray engine is an optional extra; the tests exercise it, so `make test` installs it.
$(BIN)/.ray: $(BIN)/.installed
	$(BIN)/python -m pip install --quiet -e ".[dev,ray]"
	touch $@

setup: $(BIN)/.installed

eval: setup
	$(BIN)/torchsar-eval run

test: setup $(BIN)/.ray
	$(BIN)/python -m pytest -q

lint: setup
	$(BIN)/ruff check . && $(BIN)/ruff format --check .

bench: setup
	$(BIN)/python scripts/benchmark.py

# A wheel of this repository (distribution torchsar-detect) in dist/, to install elsewhere:
# pip install torch==$(TORCH_VERSION) && pip install 'dist/torchsar_detect-<version>-py3-none-any.whl[ray]'
wheel: setup
	$(BIN)/python -m pip wheel --quiet --no-deps --no-build-isolation --wheel-dir dist .

clean:
	rm -rf $(VENV) results dist build
