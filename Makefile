# Two commands on a fresh machine with Python 3.11: `make demo` and `make test`.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DEV_STAMP := $(VENV)/.installed-dev
OUT ?= out/demo

.PHONY: demo test test-slow test-all lint bench fuzz browser teleop clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(DEV_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[dev,bench,sweep,viewer]"
	touch $@ $(STAMP)

demo: $(STAMP)
	$(BIN)/cbp compare scenarios/cat_boards.yaml --methods cat,ik,mp,jt --out $(OUT)
	@echo "Report: $(OUT)/report.md"

# Drive the arm through the boards from the browser (prints the address).
teleop: $(DEV_STAMP)
	$(BIN)/cbp teleop scenarios/cat_boards.yaml

lint: $(DEV_STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

test: lint
	$(BIN)/python -m pytest -m "not slow" -q

# The replay page is tested in a real browser: Debian's Chromium and its driver
# (installed here when missing and apt-get is allowed).
browser:
	@command -v chromium >/dev/null && command -v chromedriver >/dev/null || \
		apt-get install -y -q chromium chromium-driver >/dev/null 2>&1 || \
		(apt-get update -q >/dev/null 2>&1 && \
		 apt-get install -y -q chromium chromium-driver >/dev/null 2>&1) || \
		echo "install chromium and chromium-driver for the viewer's browser test"

test-slow: $(DEV_STAMP) browser
	$(BIN)/python -m pytest -m slow -q

test-all: lint
	$(BIN)/python -m pytest -q

# 10,000 fresh random damaged scenarios and sweep files of each kind (about
# 25 min); failures are saved in out/fuzz/.
fuzz: $(DEV_STAMP)
	CBP_FUZZ_EXAMPLES=10000 $(BIN)/python -m pytest -q -k damaged \
		tests/engine/test_loader_fuzz.py tests/sweep/test_sweep_fuzz.py

bench: $(DEV_STAMP)
	$(BIN)/cbp bench --results benchmarks/RESULTS.md --out benchmarks/results.json
	$(BIN)/python benchmarks/collision.py --append benchmarks/RESULTS.md
	$(BIN)/python benchmarks/cat_periods.py --append benchmarks/RESULTS.md

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache
