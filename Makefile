# Two commands do all set-up on a fresh machine:
#   make demo   virtual environment + install + both estimators on a bundled log + report
#   make test   the dev extras + the quick test suite (all but the tests marked slow: a few minutes)
# make test-all runs every test, the long acceptance runs too (what CI runs, .ci/run).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
DEMO_LOG := data/arena_octagon.jsonl
DEMO_OUT := out/demo
# one test process per core, at most four (pytest-xdist; each holds GTSAM, OpenCV and
# matplotlib), worksteal to even out the minutes-long acceptance runs;
# `make test PYTEST_JOBS=` runs them in one process
PYTEST_JOBS ?= -n auto --maxprocesses 4 --dist worksteal

.PHONY: demo test test-all dev install data clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

# editable_mode=compat: the work tree on sys.path by a .pth line, not setuptools' import-hook
# finder, which costs every `fgslam` command ~10 ms of start-up (pathlib, re, importlib.util)
$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e . --config-settings editable_mode=compat
	touch $@

$(VENV)/.installed-dev: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[dev]' --config-settings editable_mode=compat
	touch $(VENV)/.installed $@

install: $(VENV)/.installed

dev: $(VENV)/.installed-dev

demo: $(VENV)/.installed
	$(BIN)/fgslam run $(DEMO_LOG) --out $(DEMO_OUT)
	@echo "open $(DEMO_OUT)/report.html in a browser to see the figures"

test: $(VENV)/.installed-dev
	$(BIN)/python -m pytest $(PYTEST_JOBS) -m "not slow"

test-all: $(VENV)/.installed-dev
	$(BIN)/python -m pytest $(PYTEST_JOBS)

# Regenerate the bundled logs (deterministic: the same bytes every time).
data: $(VENV)/.installed
	$(BIN)/fgslam sim arena-octagon --seed 1 --out data/arena_octagon.jsonl --overwrite
	$(BIN)/fgslam sim arena-square --seed 1 --out data/arena_square.jsonl --overwrite

clean:
	rm -rf $(VENV) out build *.egg-info .pytest_cache .hypothesis
