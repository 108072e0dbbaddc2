# Two commands on a fresh machine with Python 3.11: `make demo` and `make test`.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DEV_STAMP := $(VENV)/.installed-dev
DOCS_STAMP := $(VENV)/.installed-docs
# MkDocs plugins print a notice about MkDocs 2 on every build; these silence it.
DOCS_ENV := DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1
OUT ?= out/demo

.PHONY: demo test test-under-load test-slow test-all lint bench fuzz browser teleop docs docs-build clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(DEV_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[dev,bench,sweep,viewer,mujoco]"
	touch $@ $(STAMP)

$(DOCS_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[docs]"
	touch $@ $(STAMP)

demo: $(STAMP)
	$(BIN)/cbp compare scenarios/cat_boards.yaml --methods cat,ik,mp,jt --out $(OUT)

# Drive the arm through the boards from the browser (prints the address).
teleop: $(DEV_STAMP)
	$(BIN)/cbp teleop scenarios/cat_boards.yaml

# The documentation site at http://127.0.0.1:8000 (reference pages generated
# from the code on every build); docs-build checks it as CI does.
docs: $(DOCS_STAMP)
	$(DOCS_ENV) $(BIN)/mkdocs serve

docs-build: $(DOCS_STAMP)
	$(DOCS_ENV) $(BIN)/mkdocs build --strict --site-dir out/site

lint: $(DEV_STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

# The fast tests on TEST_JOBS workers, a file per worker (TEST_JOBS=1: one
# process); their outcome does not depend on how busy the machine is.
TEST_JOBS ?= 2
test: lint
	$(BIN)/python -m pytest -m "not slow" -q $(if $(filter-out 1,$(TEST_JOBS)),-n $(TEST_JOBS) --dist loadfile)

# The fast suite beside two CPU-bound processes (a loaded 2-core machine): a
# test's outcome must not depend on how busy the machine is.
test-under-load: lint
	@$(BIN)/python -c "while True: pass" & one=$$!; \
	 $(BIN)/python -c "while True: pass" & two=$$!; \
	 trap 'kill $$one $$two 2>/dev/null' EXIT INT TERM; \
	 $(BIN)/python -m pytest -m "not slow" -q

# The replay page is tested in a real browser: Debian's Chromium and its driver
# (installed here when missing and apt-get is allowed).
browser:
	@command -v chromium >/dev/null && command -v chromedriver >/dev/null || \
		apt-get install -y -q chromium chromium-driver >/dev/null 2>&1 || \
		(apt-get update -q >/dev/null 2>&1 && \
		 apt-get install -y -q chromium chromium-driver >/dev/null 2>&1) || \
		echo "install chromium and chromium-driver for the viewer's browser test"

# JOBS=2 runs the slow tests on two workers, a file per worker (as CI does):
# their outcome does not depend on the machine's load, so two at a time on
# two cores holds as well.
JOBS ?= 1
test-slow: $(DEV_STAMP) browser
	$(BIN)/python -m pytest -m slow -q --durations=15 $(if $(filter-out 1,$(JOBS)),-n $(JOBS) --dist loadfile)

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
	rm -rf $(VENV) out site .pytest_cache .mypy_cache .ruff_cache
