# Two commands for a fresh machine:  make demo   (set up, then run the main job)
#                                    make test   (set up, then run the test suite)
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
# what the user's job needs (the engines, the built-in plugins, the robot drivers, MKL PARDISO);
# the test suite adds pytest, ruff and the benchmark peers (sfepy, scikit-image) and Dask
RUN_STAMP  := $(VENV)/.installed-run
TEST_STAMP := $(VENV)/.installed-test
RUN_REQS   := -e ".[fast]" -e ./plugins -e ./hardware
TEST_REQS  := -e ".[fast,test,dev,bench,cluster,table]" -e ./plugins -e ./hardware
# uv (from PyPI) resolves and installs several times faster than pip; pip when uv cannot be had.
# Byte-compiled at install, as pip does: uv does not by default, and where the environment says
# PYTHONDONTWRITEBYTECODE every process (each test worker, each CLI run, each solver worker)
# would compile its imports from source again, about two seconds each
INSTALL = if [ -x $(BIN)/uv ]; then $(BIN)/uv pip install --compile-bytecode --python $(BIN)/python $(1); \
          else $(BIN)/python -m pip install --progress-bar on $(1); fi

.PHONY: venv venv-test demo test test-e2e test-gap-quick test-gap-alternative-fe lint tox clean

venv: $(RUN_STAMP)
venv-test: $(TEST_STAMP)

$(BIN)/python:
	@echo "== creating $(VENV) with $(PYTHON)"
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check uv \
	    || echo "note: uv could not be installed; installing with pip (slower)"

$(RUN_STAMP): pyproject.toml plugins/pyproject.toml hardware/pyproject.toml | $(BIN)/python
	@echo "== installing skinkit and its plugins (what the main job needs)"
	@$(call INSTALL,$(RUN_REQS))
	touch $(RUN_STAMP)

$(TEST_STAMP): pyproject.toml plugins/pyproject.toml hardware/pyproject.toml | $(BIN)/python
	@echo "== installing skinkit with the test tools and benchmark peers"
	@$(call INSTALL,$(TEST_REQS))
	touch $(RUN_STAMP) $(TEST_STAMP)

demo: venv
	$(BIN)/skinkit demo --out demo-output

# two test workers on two cores: one BLAS/OpenMP/MKL thread each, or their spinning threads
# oversubscribe the cores (the suite took a fifth longer with the libraries' default threads)
TEST_THREADS := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1

test: venv-test
	@$(BIN)/python -m compileall -q -j 2 skinkit plugins hardware > /dev/null || true
	$(TEST_THREADS) $(BIN)/python -m pytest -n 2 --dist loadgroup -q --durations=15 -m "not e2e"; rc=$$?; if [ $$rc -eq 5 ]; then echo "no tests collected"; exit 0; fi; exit $$rc

# the main job end to end (the quick demo's chain, its checks of every step): a fifth of the
# suite's processor time on its own, so kept out of `make test`; CI (.ci/run) runs it after the suite
test-e2e: venv-test
	$(TEST_THREADS) $(BIN)/python -m pytest -q -m e2e --durations=5 tests/pipelines

# the quick FE gap benchmark and its figures: kept out of `make test` (which stays under
# 10 minutes); CI (.ci/run) runs it after the suite
test-gap-quick: venv-test
	SKINKIT_GAP_QUICK=1 $(BIN)/python -m pytest -q -s tests/gap/test_benchmark_quick.py

test-gap-alternative-fe: venv-test
	SKINKIT_GAP_ALTERNATIVE_FE=1 $(BIN)/python -m pytest -q -s tests/gap/test_benchmark_alternative_fe_quick.py

# the region scan through whole diagnoses of two two-pad sessions (a scar, and none): about 8
# minutes on one core, kept out of `make test`
test-gap-scan: venv-test
	SKINKIT_GAP_SCAN=1 $(BIN)/python -m pytest -q -s tests/gap/test_scan_diagnose.py

lint: venv-test
	$(BIN)/ruff check skinkit plugins hardware tests

# With pyenv, make every installed 3.10-3.13 visible to tox at once.
tox: venv-test
	PYENV_VERSION="$$(pyenv versions --bare 2>/dev/null | grep -E '^3\.1[0-3]\.' | paste -sd: -)" $(BIN)/tox

clean:
	rm -rf $(VENV) demo-output .tox
