# The two commands of the README. Each creates the virtual environment and installs the
# package first, so a fresh machine needs only Python >= 3.10.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
RESULTS ?= results
# The folder of real data sets (fsdd, msr-action3d, eth80, ...); empty: $$MMCONCEPTS_DATA_ROOT, else generated data only.
DATA_ROOT ?=

.PHONY: reproduce test test-fast golden browser typecheck docs bench clean

# Installs into the environment with uv (itself installed from PyPI into the environment), which installs the same
# packages in about half pip's time (benchmarks/README.md); with pip when uv cannot be had or fails. Both write the
# byte code of what they install, as pip does by default. uv reads the system's certificates, as pip does.
comma := ,
define install
	if { $(BIN)/python -m uv --version || $(BIN)/python -m pip install --quiet uv; } >/dev/null 2>&1 && \
	   UV_SYSTEM_CERTS=1 UV_NATIVE_TLS=1 $(BIN)/python -m uv pip install --quiet --python $(BIN)/python \
	     --compile-bytecode $(1); then :; \
	else echo "note: installing with pip (uv is not available or failed)"; \
	  $(BIN)/python -m pip install --quiet --upgrade pip && $(BIN)/python -m pip install --quiet $(1); fi
endef

# The byte code of the package's own modules, which an editable install leaves to be written on first import: where
# that is off (PYTHONDONTWRITEBYTECODE), every process of a run would compile them again. Written before each run;
# files already up to date are skipped.
COMPILE_PACKAGE = $(BIN)/python -m compileall -q src/mmconcepts > /dev/null

# The package with every modality (extra "all"); the experiments add the text-to-speech that speaks the generated
# caregiver corpus (extra "speech"), the tests and the benchmarks their tools.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(call install,-e ".[all]")
	touch $(STAMP)

$(VENV)/.installed-%: $(STAMP)
	$(call install,-e ".[all$(comma)$*]")
	touch $@

# The tests check the types and build the documentation too (what CI runs).
$(VENV)/.installed-dev: $(STAMP)
	$(call install,-e ".[dev]")
	touch $@

## Run every registered experiment in quick mode, on the real sets of DATA_ROOT and on generated data,
## and write results/report.html and results/report.md (two experiments at a time, on two processes that run one
## after another, each with a worker per core: what one leaves idle, the other uses; shared caches and numba's
## compiled kernels are made once, under a lock)
reproduce: $(VENV)/.installed-speech
	$(COMPILE_PACKAGE)
	$(BIN)/mmconcepts reproduce --quick --workers -1 --concurrent 2 --output $(RESULTS) $(if $(DATA_ROOT),--data-root $(DATA_ROOT))

## Run the test-suite (slow tests included), then the type check and the documentation build (what CI runs)
test: $(VENV)/.installed-dev browser
	$(COMPILE_PACKAGE)
	$(BIN)/python -m pytest -q
	$(MAKE) --no-print-directory typecheck docs

## The fast tests only (no test marked slow, no type check or documentation build): a few minutes, for the edit-test
## loop; CI runs `make test`
test-fast: $(VENV)/.installed-dev
	$(BIN)/python -m pytest -q -m "not slow"

# The golden set: the experiments whose smoke records are kept in tests/golden/ (every experiment declares a smoke
# preset, for its own tests; only these records are kept)
GOLDEN_IDS ?= $(sort $(basename $(notdir $(wildcard tests/golden/*.json))))

## Rewrite tests/golden/, the smoke records of the golden set (at least one experiment per chapter, on generated data,
## against which tests/experiments/test_golden_records.py compares), after a change meant to change their results;
## GOLDEN_IDS="ID ..." makes those experiments the golden set. They run in the numerical environment of
## tests/golden_platform.py (every library held to x86-64-v3), with their own cache folder, and tests/golden/PLATFORM
## names this CPU's class.
golden: $(VENV)/.installed-dev
	rm -rf $(VENV)/golden-run $(VENV)/golden-cache
	MMCONCEPTS_DATA_ROOT= MMCONCEPTS_DATA=$(VENV)/golden-cache $(BIN)/python tests/golden_platform.py \
	  --write-class $(VENV)/golden-platform \
	  $(BIN)/mmconcepts reproduce --smoke --only $(GOLDEN_IDS) --workers 2 --output $(VENV)/golden-run
	rm -f tests/golden/*.json
	cp $(VENV)/golden-run/*.json tests/golden/
	cp $(VENV)/golden-platform tests/golden/PLATFORM

## Install headless Chromium and its driver (Debian packages) for tests/report/test_browser.py when they are
## missing and this user may (root, or passwordless sudo); otherwise do nothing (that test then skips, saying why)
browser:
	@if command -v chromium >/dev/null 2>&1 && command -v chromedriver >/dev/null 2>&1; then :; \
	elif ! command -v apt-get >/dev/null 2>&1; then \
	  echo "note: no chromium/chromedriver and no apt-get: the report's browser test will skip"; \
	else \
	  if [ "$$(id -u)" = 0 ]; then SUDO=; elif sudo -n true 2>/dev/null; then SUDO="sudo -n"; else SUDO=none; fi; \
	  if [ "$$SUDO" = none ]; then \
	    echo "note: chromium/chromedriver missing and not root: the report's browser test will skip"; \
	  else \
	    echo "installing chromium and chromium-driver (apt-get) for the report's browser test"; \
	    $$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver >/dev/null 2>&1 \
	    || { $$SUDO apt-get update -q >/dev/null 2>&1 && \
	         $$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver >/dev/null 2>&1; } \
	    || echo "note: could not install chromium: the report's browser test will skip"; \
	  fi; \
	fi

## Type-check the package (mypy; configuration in pyproject.toml)
typecheck: $(VENV)/.installed-dev
	$(BIN)/python -m mypy

# The data root of the gallery examples that use real sets: DATA_ROOT, else $$MMCONCEPTS_DATA_ROOT, else the data
# folder that the project's CI machines place beside the checkout, when it exists (else generated stand-ins)
DOCS_DATA_ROOT ?= $(or $(DATA_ROOT),$(MMCONCEPTS_DATA_ROOT),$(wildcard ../shared/data))

## Build the documentation site into docs/_build/html (warnings are errors)
docs: $(VENV)/.installed-dev
	MMCONCEPTS_DATA_ROOT="$(DOCS_DATA_ROOT)" $(BIN)/python -m sphinx -W --keep-going -q -b html docs docs/_build/html

## Speed comparisons against the peer libraries (see benchmarks/README.md)
bench: $(VENV)/.installed-bench
	$(BIN)/python benchmarks/nmf.py
	$(BIN)/python benchmarks/dtw.py
	$(BIN)/python benchmarks/tree.py
	$(BIN)/python benchmarks/mdp.py
	$(BIN)/python benchmarks/coefficients.py
	$(BIN)/python benchmarks/codebooks.py

clean:
	rm -rf $(VENV) $(RESULTS) .pytest_cache .mypy_cache tests/.artifacts docs/_build docs/auto_examples docs/api/generated docs/sg_execution_times.rst
