# Two commands for a fresh machine:  make demo   (set up, then run the main job)
#                                    make test   (set up, then run the test suite)
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: venv demo test lint tox clean

venv: $(STAMP)

$(STAMP): pyproject.toml plugins/pyproject.toml hardware/pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,dev,bench,cluster]" -e ./plugins -e ./hardware
	touch $(STAMP)

demo: venv
	$(BIN)/skinkit demo --out demo-output

test: venv
	$(BIN)/python -m pytest -n 2 -q; rc=$$?; if [ $$rc -eq 5 ]; then echo "no tests collected"; exit 0; fi; exit $$rc

lint: venv
	$(BIN)/ruff check skinkit plugins hardware tests

# With pyenv, make every installed 3.10-3.13 visible to tox at once.
tox: venv
	PYENV_VERSION="$$(pyenv versions --bare 2>/dev/null | grep -E '^3\.1[0-3]\.' | paste -sd: -)" $(BIN)/tox

clean:
	rm -rf $(VENV) demo-output .tox
