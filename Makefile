# One-command set-up: `make eval` runs the default evaluation, `make test` runs the tests.
# torch is installed first and pinned: an unpinned torch pulls a multi-GB CUDA build.
# Bytecode caches on, whatever the shell says: a machine with PYTHONDONTWRITEBYTECODE set
# compiles every module from source in each of the test run's processes (collection alone
# took 18 s instead of 11 s on the 2-core VM).
unexport PYTHONDONTWRITEBYTECODE

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
TORCH_VERSION ?= 2.13.0

.PHONY: setup eval test test-integration test-browser browser coverage lint docs bench wheel clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet torch==$(TORCH_VERSION)
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $@

# The Ray engine is an optional extra; the integration tests exercise it, so CI's `make test`
# and `make test-integration` install it: the extra's requirements as pyproject.toml lists
# them (without rebuilding the project). The default test run does not need it.
RAY_EXTRA = import tomllib; print(*tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]["ray"])
$(BIN)/.ray: $(BIN)/.installed
	$(BIN)/python -m pip install --quiet $$($(BIN)/python -c '$(RAY_EXTRA)')
	touch $@

# numba compiles its kernels on first use (about a minute for all of them), and the K / G0
# CFARs calibrate their log-t factors (a few seconds, kept in ~/.cache/torchsar): pay both
# here, once per change of a kernel file or of the calibration, instead of in the first
# evaluation or test run.
KERNELS := $(filter-out torchsar/_gpu_kernels.py,$(wildcard torchsar/*_kernels.py torchsar/*/_kernels.py)) torchsar/_block_sums.py torchsar/_vector_exp.py torchsar/cfar/log_t.py
$(BIN)/.kernels: $(BIN)/.installed $(KERNELS) torchsar/_warm.py scripts/warm_kernels.py
	$(BIN)/python scripts/warm_kernels.py
	touch $@

setup: $(BIN)/.installed $(BIN)/.kernels

eval: setup
	$(BIN)/torchsar-eval run

# The browser test of report.html (slow, skipped without Chromium) needs a headless Chromium:
# `make browser` installs Debian's with apt-get when none is on PATH (root, or sudo without a
# password). In CI (CI set) `make test` does so and runs the browser test too.
BROWSERS     := chromium chromium-browser google-chrome google-chrome-stable
BROWSER_TEST := tests/eval/test_report_browser.py

browser:
	@for b in $(BROWSERS); do command -v $$b >/dev/null 2>&1 && exit 0; done; \
	SUDO=$$([ "$$(id -u)" = 0 ] || echo "sudo -n"); \
	$$SUDO apt-get update -qq && \
	DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends chromium

# Installing Chromium may fail (no root, no mirror): then the browser test is skipped, never red.
# In CI (CI set) a second step runs the integration tests (worker pools, Ray, kills, the
# documentation's long pages); `pytest -m slow` runs the long exhaustive and fuzz cases.
# The suite runs in TEST_WORKERS processes (pytest-xdist; 2: CI's cores): 0.7x the serial
# wall time on the 2-core VM. TEST_WORKERS=0 runs it in this process.
TEST_WORKERS ?= 2
test: setup
	$(if $(CI),-timeout 600 $(MAKE) --no-print-directory browser)
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS)
	$(if $(CI),$(MAKE) --no-print-directory test-integration)
	$(if $(CI),$(BIN)/python -m pytest -q -m slow $(BROWSER_TEST))

# The engine's integration tests (worker pools, Ray, kills, fresh processes): CI's second step.
test-integration: setup $(BIN)/.ray
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) -m integration

# Statement coverage of the library and the harness (in-process code; the command lines the
# tests start are not traced): `make coverage` for the default run, MARK=integration for CI's
# second step, MARK="not slow" for both. The sources are named as folders: the doctests
# import eval/*.py under other module names first, and a package name (torchsar_eval) would
# then leave those files untraced (coverage decides once per file).
MARK ?= not slow and not integration
coverage: setup $(BIN)/.ray
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) -m "$(MARK)" \
		--cov=torchsar --cov=eval --cov-report=term:skip-covered | grep -E "^(Name|TOTAL)|passed|failed"

test-browser: setup browser
	$(BIN)/python -m pytest -q -m slow $(BROWSER_TEST)

lint: setup
	$(BIN)/ruff check . && $(BIN)/ruff format --check .

# The documentation site (docs/, mkdocs.yml) into site/, warnings as errors (broken links,
# missing references, docstrings that do not parse).
$(BIN)/.docs: $(BIN)/.installed
	$(BIN)/python -m pip install --quiet -e ".[docs]"
	touch $@

docs: $(BIN)/.docs
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

bench: setup
	$(BIN)/python scripts/benchmark.py

# A wheel of this repository (distribution torchsar-detect) in dist/, to install elsewhere:
# pip install torch==$(TORCH_VERSION) && pip install 'dist/torchsar_detect-<version>-py3-none-any.whl[ray]'
wheel: setup
	$(BIN)/python -m pip wheel --quiet --no-deps --no-build-isolation --wheel-dir dist .

clean:
	rm -rf $(VENV) results dist build
